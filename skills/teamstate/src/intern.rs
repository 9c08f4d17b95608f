//! One copy of each bulky record body per process.
//!
//! Every robot of a team holds every scan and the latest map version of every mapping robot.
//! Robots simulated in one process (and the robot processes' own copies from a snapshot and a
//! peer) would each hold a decoded copy: a team of N UGVs holds N copies of each of the team's
//! scans, N² in all. Interning a record's body as it enters a team state leaves one copy of
//! each distinct body, shared by every team state holding it. The body is compared in full
//! before it is shared, so sharing changes no result.

use std::collections::HashMap;
use std::hash::Hash;
use std::sync::{Arc, LazyLock, Mutex, PoisonError, RwLock, Weak};

use spomp_core::{ReachabilityScan, RobotId};

use crate::record::{RecordBody, RecordKey};

/// Live values by a key that tells most of them apart; equal keys may hold different values
/// (trials run side by side in one process reuse robot names and numbers).
struct Interner<K, T> {
    entries: HashMap<K, Vec<Weak<T>>>,
    /// Values added since dead entries were last dropped.
    added_since_prune: usize,
}

impl<K: Eq + Hash, T: PartialEq> Interner<K, T> {
    fn new() -> Self {
        Interner { entries: HashMap::new(), added_since_prune: 0 }
    }

    /// The live value equal to `value` filed under `key`, or `value` itself, now filed.
    fn intern(&mut self, key: K, value: &Arc<T>) -> Arc<T> {
        let candidates = self.entries.entry(key).or_default();
        candidates.retain(|w| w.strong_count() > 0);
        if let Some(found) =
            candidates.iter().filter_map(Weak::upgrade).find(|v| Arc::ptr_eq(v, value) || **v == **value)
        {
            return found;
        }
        candidates.push(Arc::downgrade(value));
        self.added_since_prune += 1;
        // Drop the keys whose values all died, at a cost proportional to the additions.
        if self.added_since_prune > self.entries.len().max(256) / 2 {
            self.entries.retain(|_, list| {
                list.retain(|w| w.strong_count() > 0);
                !list.is_empty()
            });
            self.added_since_prune = 0;
        }
        Arc::clone(value)
    }
}

/// An interner shared by the whole process, filing values by writer and number.
type ProcessInterner<T> = LazyLock<Mutex<Interner<(RobotId, u64), T>>>;

/// Scans by taker and sequence number.
static SCANS: ProcessInterner<ReachabilityScan> = LazyLock::new(|| Mutex::new(Interner::new()));

/// Compressed map versions by publisher and version.
static MAP_BLOBS: ProcessInterner<Vec<u8>> = LazyLock::new(|| Mutex::new(Interner::new()));

/// A record key's process-wide number ([`key_no`]). Immutable keys and mutable ones are
/// numbered apart, each from 0, so a per-peer table holds a bit for the first (their only dot
/// is 1) and a dot for the second, and what a robot keeps per record and per peer (its change
/// log, the records pending for each peer) is a number instead of a key.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub(crate) struct KeyNo(u64);

/// Set in the number of a mutable key.
const MUTABLE_BIT: u64 = 1 << 63;

impl KeyNo {
    /// Whether the key's records are immutable.
    pub fn is_immutable(self) -> bool {
        self.0 & MUTABLE_BIT == 0
    }

    /// The key's index among the keys of its mutability.
    pub fn index(self) -> usize {
        (self.0 & !MUTABLE_BIT) as usize
    }
}

/// Every record key seen in the process, numbered in the order first seen (see [`KeyNo`]).
#[derive(Default)]
pub(crate) struct KeyTable {
    numbers: HashMap<RecordKey, KeyNo>,
    immutable: Vec<RecordKey>,
    mutable: Vec<RecordKey>,
}

impl KeyTable {
    /// The key numbered `no`.
    pub fn key(&self, no: KeyNo) -> Option<&RecordKey> {
        let keys = if no.is_immutable() { &self.immutable } else { &self.mutable };
        keys.get(no.index())
    }
}

/// Read-mostly: a key is numbered once, then only looked up (by every robot of every trial run
/// side by side in the process, which must not wait for each other).
static KEY_NUMBERS: LazyLock<RwLock<KeyTable>> = LazyLock::new(|| RwLock::new(KeyTable::default()));

/// The process-wide number of a record key (given one on first sight).
pub(crate) fn key_no(key: &RecordKey) -> KeyNo {
    if let Some(&no) = KEY_NUMBERS.read().unwrap_or_else(PoisonError::into_inner).numbers.get(key) {
        return no;
    }
    let mut table = KEY_NUMBERS.write().unwrap_or_else(PoisonError::into_inner);
    // Numbered by another thread between the two locks?
    if let Some(&no) = table.numbers.get(key) {
        return no;
    }
    let no = if key.is_immutable() {
        table.immutable.push(key.clone());
        KeyNo(table.immutable.len() as u64 - 1)
    } else {
        table.mutable.push(key.clone());
        KeyNo((table.mutable.len() as u64 - 1) | MUTABLE_BIT)
    };
    table.numbers.insert(key.clone(), no);
    no
}

/// Runs `f` with the table of numbered keys (one lock for many look-ups; `f` must not number
/// keys itself).
pub(crate) fn with_keys<R>(f: impl FnOnce(&KeyTable) -> R) -> R {
    f(&KEY_NUMBERS.read().unwrap_or_else(PoisonError::into_inner))
}

/// Replaces a scan or map body by the process's copy of it, if there is one (else files it).
pub(crate) fn share_body(key: &RecordKey, body: &mut RecordBody) {
    match (key, body) {
        (RecordKey::Scan { robot, seq }, RecordBody::Scan(scan)) => {
            let mut scans = SCANS.lock().unwrap_or_else(PoisonError::into_inner);
            *scan = scans.intern((robot.clone(), *seq), scan);
        }
        (RecordKey::Map(robot), RecordBody::Map(map)) => {
            let mut blobs = MAP_BLOBS.lock().unwrap_or_else(PoisonError::into_inner);
            map.blob = blobs.intern((robot.clone(), map.version), &map.blob);
        }
        _ => {}
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn equal_values_share_one_copy_and_different_ones_do_not() {
        let mut interner = Interner::new();
        let a = Arc::new(vec![1u8, 2, 3]);
        let a_again = Arc::new(vec![1u8, 2, 3]);
        let other_trial = Arc::new(vec![9u8]);
        assert!(Arc::ptr_eq(&interner.intern("k", &a), &a));
        assert!(Arc::ptr_eq(&interner.intern("k", &a_again), &a), "an equal copy gives the filed one");
        assert!(Arc::ptr_eq(&interner.intern("k", &other_trial), &other_trial), "same key, other value");
        drop(a);
        let after = Arc::new(vec![1u8, 2, 3]);
        // `a_again` is still alive and equal.
        assert_eq!(*interner.intern("k", &after), vec![1, 2, 3]);
    }

    #[test]
    fn record_keys_keep_their_number() {
        let a = RecordKey::Robot(RobotId::new("intern-test-a"));
        let b = RecordKey::Map(RobotId::new("intern-test-a"));
        let na = key_no(&a);
        let nb = key_no(&b);
        assert_ne!(na, nb);
        assert_eq!(key_no(&a.clone()), na);
        assert!(!na.is_immutable() && !nb.is_immutable());
        // Immutable keys are numbered apart.
        let scan = |seq| RecordKey::Scan { robot: RobotId::new("intern-test-a"), seq };
        let (s0, s1) = (key_no(&scan(0)), key_no(&scan(1)));
        assert!(s0.is_immutable() && s1.is_immutable());
        assert_ne!(s0, s1);
        assert_eq!(key_no(&scan(1)), s1);
        // Numbers give their keys back.
        with_keys(|table| {
            assert_eq!(table.key(na), Some(&a));
            assert_eq!(table.key(nb), Some(&b));
            assert_eq!(table.key(s1), Some(&scan(1)));
        });
    }

    #[test]
    fn dead_keys_are_dropped() {
        let mut interner = Interner::new();
        for k in 0..10_000u32 {
            let v = Arc::new(k);
            interner.intern(k, &v);
        }
        assert!(interner.entries.len() < 1_000, "{} keys kept for dead values", interner.entries.len());
    }
}
