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
use std::sync::{Arc, LazyLock, Mutex, PoisonError, Weak};

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

/// Every record key seen in the process, numbered in the order first seen, immutable keys and
/// mutable ones each from 0: what a robot tracks per peer is then a dense table by number
/// ([`crate::sync::DotsByKey`]) instead of a map of keys (for each peer of each robot: the
/// team state's largest part in a large team, which every robot holds about every other). The
/// immutable records (scans, goals, visits: nearly all of them) need one bit there, the mutable
/// ones a dot.
struct KeyNumbers {
    numbers: HashMap<RecordKey, usize>,
    immutable: usize,
    mutable: usize,
}

static KEY_NUMBERS: LazyLock<Mutex<KeyNumbers>> =
    LazyLock::new(|| Mutex::new(KeyNumbers { numbers: HashMap::new(), immutable: 0, mutable: 0 }));

/// The process-wide number of a record key among the keys of its mutability (given one on
/// first sight).
pub(crate) fn key_number(key: &RecordKey) -> usize {
    let mut table = KEY_NUMBERS.lock().unwrap_or_else(PoisonError::into_inner);
    if let Some(&n) = table.numbers.get(key) {
        return n;
    }
    let counter = if key.is_immutable() { &mut table.immutable } else { &mut table.mutable };
    let n = *counter;
    *counter += 1;
    table.numbers.insert(key.clone(), n);
    n
}

/// The number of a record key seen before; `None` for a key never seen in the process.
pub(crate) fn known_key_number(key: &RecordKey) -> Option<usize> {
    KEY_NUMBERS.lock().unwrap_or_else(PoisonError::into_inner).numbers.get(key).copied()
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
        assert_eq!(known_key_number(&a), None);
        let na = key_number(&a);
        let nb = key_number(&b);
        assert_ne!(na, nb);
        assert_eq!(key_number(&a.clone()), na);
        assert_eq!(known_key_number(&b), Some(nb));
        // Immutable keys are numbered apart, and as tightly.
        let s0 = key_number(&RecordKey::Scan { robot: RobotId::new("intern-test-a"), seq: 0 });
        let s1 = key_number(&RecordKey::Scan { robot: RobotId::new("intern-test-a"), seq: 1 });
        assert_ne!(s0, s1);
        assert_eq!(known_key_number(&RecordKey::Scan { robot: RobotId::new("intern-test-a"), seq: 1 }), Some(s1));
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
