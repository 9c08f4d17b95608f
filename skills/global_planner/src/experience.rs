//! Edge states from experience (trav / not_trav / unk_trav) and per-cell training votes.

use serde::Serialize;

use crate::params::ExperienceParams;
use crate::star::EdgeObservation;

/// What experience says about an edge.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum EdgeState {
    /// Not determined yet: the edge costs what the map predicts.
    #[default]
    Unknown,
    /// Observed traversable: a very high traversal probability overrides the prediction.
    Trav,
    /// Observed not traversable: a very low probability (removed if locked).
    NotTrav,
}

/// Observation history of one edge.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(crate) struct EdgeExperience {
    pub state: EdgeState,
    /// Marked not_trav from the robot's own observations: never changes again.
    pub locked: bool,
    trav_streak: u32,
    not_trav_streak: u32,
    own_not_trav_streak: u32,
}

/// Effect of an observation on an edge.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Transition {
    /// Same state.
    None,
    /// The state changed (costs must be refreshed).
    Changed,
    /// The edge became not_trav and locked: remove it for good.
    Removed,
}

impl EdgeExperience {
    /// Takes one observation. Consistent observations accumulate in streaks; a contrary one
    /// resets them; unk_trav carries no information and leaves them alone. Only the robot's own
    /// observations can lock an edge (and so remove it).
    pub fn observe(&mut self, obs: EdgeObservation, own: bool, p: &ExperienceParams) -> Transition {
        if self.locked {
            return Transition::None;
        }
        let before = self.state;
        match obs {
            EdgeObservation::UnkTrav => return Transition::None,
            EdgeObservation::Trav => {
                self.trav_streak = self.trav_streak.saturating_add(1);
                self.not_trav_streak = 0;
                self.own_not_trav_streak = 0;
                if self.trav_streak >= p.observations_to_mark.max(1) {
                    self.state = EdgeState::Trav;
                }
            }
            EdgeObservation::NotTrav => {
                self.trav_streak = 0;
                self.not_trav_streak = self.not_trav_streak.saturating_add(1);
                if own {
                    self.own_not_trav_streak = self.own_not_trav_streak.saturating_add(1);
                }
                let needed = if self.state == EdgeState::Trav {
                    p.observations_to_overturn_trav.max(1)
                } else {
                    p.observations_to_mark.max(1)
                };
                if self.own_not_trav_streak >= needed {
                    self.state = EdgeState::NotTrav;
                    self.locked = true;
                    return Transition::Removed;
                }
                if self.not_trav_streak >= needed {
                    self.state = EdgeState::NotTrav;
                }
            }
        }
        if self.state == before { Transition::None } else { Transition::Changed }
    }
}

impl EdgeExperience {
    /// The robot itself failed to drive the edge (it made no progress along it): the most
    /// direct of its own observations, so the edge is marked not_trav and locked at once, as
    /// its own not_trav scans lock an edge (removed for good). Already locked: nothing changes.
    pub fn failed_drive(&mut self) -> Transition {
        if self.locked {
            return Transition::None;
        }
        self.state = EdgeState::NotTrav;
        self.locked = true;
        self.trav_streak = 0;
        Transition::Removed
    }
}

/// Per-cell votes from scans: +1 inside a safe region, −1 just beyond a known obstacle; each scan
/// votes at most once per cell.
///
/// One byte a cell for the net votes and two bits a cell for the bookkeeping: every UGV of a
/// team holds this over the whole map, while a scan touches a few thousand cells.
#[derive(Clone, Debug, Default)]
pub(crate) struct Votes {
    votes: Vec<i8>,
    /// Cells that ever received a vote (bit per cell).
    ever_voted: Vec<u64>,
    /// Cells the current scan voted on (bit per cell), cleared through `voted_now`.
    voted_this_scan: Vec<u64>,
    /// The cells whose `voted_this_scan` bit is set.
    voted_now: Vec<u32>,
    /// Cells in the order of their first vote (the order labels come out in).
    touched: Vec<u32>,
}

/// Word and mask of a cell's bit.
#[inline]
fn bit(cell: usize) -> (usize, u64) {
    (cell / 64, 1u64 << (cell % 64))
}

impl Votes {
    /// Sizes the rasters for `cells` cells (keeps votes when the size is unchanged).
    pub fn resize(&mut self, cells: usize) {
        if self.votes.len() != cells {
            let words = cells.div_ceil(64);
            self.votes = vec![0; cells];
            self.ever_voted = vec![0; words];
            self.voted_this_scan = vec![0; words];
            self.voted_now.clear();
            self.touched.clear();
        }
    }

    /// Starts a new scan.
    pub fn begin_scan(&mut self) {
        for &cell in &self.voted_now {
            let (word, _) = bit(cell as usize);
            self.voted_this_scan[word] = 0;
        }
        self.voted_now.clear();
    }

    /// Casts this scan's vote on a cell; returns false when the scan already voted there.
    pub fn vote(&mut self, cell: usize, traversable: bool) -> bool {
        let Some(v) = self.votes.get_mut(cell) else {
            return false;
        };
        let (word, mask) = bit(cell);
        if self.voted_this_scan[word] & mask != 0 {
            return false;
        }
        self.voted_this_scan[word] |= mask;
        self.voted_now.push(cell as u32);
        if self.ever_voted[word] & mask == 0 {
            self.ever_voted[word] |= mask;
            self.touched.push(cell as u32);
        }
        *v = if traversable { v.saturating_add(1) } else { v.saturating_sub(1) };
        true
    }

    /// Cells with at least `needed` net votes either way, with their label (true = traversable).
    pub fn labels(&self, needed: u8) -> impl Iterator<Item = (usize, bool)> + '_ {
        let needed = needed.max(1) as i8;
        self.touched.iter().filter_map(move |&c| {
            let v = self.votes[c as usize];
            (v >= needed || v <= -needed).then_some((c as usize, v > 0))
        })
    }

    /// Net votes of a cell.
    pub fn net(&self, cell: usize) -> i8 {
        self.votes.get(cell).copied().unwrap_or(0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use EdgeObservation::*;

    #[test]
    fn two_own_not_trav_observations_remove() {
        let p = ExperienceParams::default();
        let mut e = EdgeExperience::default();
        assert_eq!(e.observe(NotTrav, true, &p), Transition::None);
        assert_eq!(e.observe(NotTrav, true, &p), Transition::Removed);
        assert!(e.locked);
        assert_eq!(e.observe(Trav, true, &p), Transition::None, "locked forever");
    }

    #[test]
    fn a_failed_drive_locks_the_edge_not_trav_at_once() {
        let p = ExperienceParams::default();
        let mut e = EdgeExperience::default();
        e.observe(Trav, true, &p);
        e.observe(Trav, true, &p);
        assert_eq!(e.state, EdgeState::Trav);
        assert_eq!(e.failed_drive(), Transition::Removed);
        assert!(e.locked && e.state == EdgeState::NotTrav);
        assert_eq!(e.observe(Trav, false, &p), Transition::None, "no scan brings it back");
        assert_eq!(e.failed_drive(), Transition::None);
    }

    #[test]
    fn other_robots_mark_but_never_lock() {
        let p = ExperienceParams::default();
        let mut e = EdgeExperience::default();
        for _ in 0..10 {
            assert_ne!(e.observe(NotTrav, false, &p), Transition::Removed);
        }
        assert_eq!(e.state, EdgeState::NotTrav);
        assert!(!e.locked);
        e.observe(Trav, false, &p);
        assert_eq!(e.observe(Trav, false, &p), Transition::Changed);
        assert_eq!(e.state, EdgeState::Trav);
    }

    #[test]
    fn trav_needs_more_evidence_to_overturn_and_contrary_evidence_resets() {
        let p = ExperienceParams::default();
        let mut e = EdgeExperience::default();
        e.observe(Trav, true, &p);
        e.observe(Trav, true, &p);
        assert_eq!(e.state, EdgeState::Trav);
        e.observe(NotTrav, true, &p);
        e.observe(NotTrav, true, &p);
        e.observe(UnkTrav, true, &p);
        e.observe(NotTrav, true, &p);
        assert_eq!(e.state, EdgeState::Trav, "3 < 4 observations");
        e.observe(Trav, true, &p);
        for _ in 0..3 {
            e.observe(NotTrav, true, &p);
        }
        assert_eq!(e.state, EdgeState::Trav, "streak was reset");
        assert_eq!(e.observe(NotTrav, true, &p), Transition::Removed);
    }

    #[test]
    fn one_vote_per_scan_and_label_threshold() {
        let mut v = Votes::default();
        v.resize(4);
        for _ in 0..3 {
            v.begin_scan();
            assert!(v.vote(1, true));
            assert!(!v.vote(1, true));
            v.vote(2, false);
        }
        v.begin_scan();
        v.vote(2, true);
        let labels: Vec<_> = v.labels(3).collect();
        assert_eq!(labels, vec![(1, true)], "cell 2 has only 2 net votes");
        assert!(!v.vote(99, true));
    }

    #[test]
    fn labels_keep_the_order_of_first_votes_across_word_boundaries() {
        let mut v = Votes::default();
        v.resize(200);
        let cells = [130usize, 3, 64, 63, 199, 3];
        for _ in 0..2 {
            v.begin_scan();
            for &c in &cells {
                v.vote(c, c % 2 == 1);
            }
        }
        let labels: Vec<_> = v.labels(2).collect();
        assert_eq!(labels, vec![(130, false), (3, true), (64, false), (63, true), (199, true)]);
        v.begin_scan();
        assert!(v.vote(64, true), "a new scan may vote again on every cell");
        assert_eq!(v.net(64), -1);
    }
}
