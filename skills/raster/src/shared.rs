//! A process-wide list of values derived from map contents, shared by every holder: robots of a
//! team (and trials run side by side) that hold the same map build such a value once. Entries
//! are weak, so a value lives only as long as someone holds it.

use std::collections::HashMap;
use std::hash::Hash;
use std::sync::{Arc, Mutex, PoisonError, Weak};

/// The live values of one kind in the process; a `static` of each kind serves everyone.
#[derive(Debug, Default)]
pub struct SharedList<T> {
    live: Mutex<Vec<Weak<T>>>,
}

impl<T> SharedList<T> {
    /// An empty list.
    pub const fn new() -> Self {
        SharedList { live: Mutex::new(Vec::new()) }
    }

    /// A live value that `matches`, if someone holds one (dead entries are dropped on the way).
    pub fn find(&self, matches: impl Fn(&T) -> bool) -> Option<Arc<T>> {
        let mut live = self.live.lock().unwrap_or_else(PoisonError::into_inner);
        live.retain(|w| w.strong_count() > 0);
        live.iter().filter_map(Weak::upgrade).find(|v| matches(v))
    }

    /// Offers `value` to the others and returns what to hold: a live value that `matches`, if
    /// another holder offered one meanwhile (built side by side), so every holder keeps one;
    /// else `value`.
    pub fn share(&self, value: Arc<T>, matches: impl Fn(&T) -> bool) -> Arc<T> {
        let mut live = self.live.lock().unwrap_or_else(PoisonError::into_inner);
        if let Some(first) = live.iter().filter_map(Weak::upgrade).find(|v| matches(v)) {
            return first;
        }
        live.push(Arc::downgrade(&value));
        value
    }
}

/// A process-wide memo of a pure function's results, keyed by everything the function reads
/// (map contents by their fingerprints): robots of a team that ask the same question get the
/// answer computed once. Holds at most `capacity` answers and forgets them all when full; an
/// answer is the same whoever computed it, so what is remembered never changes a result.
#[derive(Debug)]
pub struct SharedMemo<K, V> {
    capacity: usize,
    answers: Mutex<Option<HashMap<K, V>>>,
}

impl<K: Eq + Hash, V: Clone> SharedMemo<K, V> {
    /// An empty memo holding at most `capacity` answers.
    pub const fn new(capacity: usize) -> Self {
        SharedMemo { capacity, answers: Mutex::new(None) }
    }

    /// The answer remembered for `key`, if any.
    pub fn get(&self, key: &K) -> Option<V> {
        let answers = self.answers.lock().unwrap_or_else(PoisonError::into_inner);
        answers.as_ref().and_then(|a| a.get(key)).cloned()
    }

    /// Remembers `value` as the answer for `key` (forgetting every answer first when full).
    pub fn remember(&self, key: K, value: V) {
        let mut answers = self.answers.lock().unwrap_or_else(PoisonError::into_inner);
        let answers = answers.get_or_insert_with(HashMap::new);
        if answers.len() >= self.capacity {
            answers.clear();
        }
        answers.insert(key, value);
    }

    /// Forgets every answer (a benchmark that measures the search itself starts cold).
    pub fn clear(&self) {
        if let Some(answers) = self.answers.lock().unwrap_or_else(PoisonError::into_inner).as_mut() {
            answers.clear();
        }
    }

    /// Answers remembered now.
    pub fn len(&self) -> usize {
        self.answers.lock().unwrap_or_else(PoisonError::into_inner).as_ref().map_or(0, HashMap::len)
    }

    /// Whether nothing is remembered.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn answers_are_remembered_up_to_the_capacity() {
        let memo = SharedMemo::new(2);
        assert_eq!(memo.get(&1), None);
        memo.remember(1, "one");
        memo.remember(2, "two");
        assert_eq!((memo.get(&1), memo.get(&2), memo.len()), (Some("one"), Some("two"), 2));
        // Full: the third answer starts a fresh memo.
        memo.remember(3, "three");
        assert_eq!((memo.get(&1), memo.get(&3), memo.len()), (None, Some("three"), 1));
        memo.clear();
        assert!(memo.is_empty());
    }

    #[test]
    fn values_are_found_while_held_and_shared_once() {
        let list = SharedList::new();
        let a = list.share(Arc::new(7), |v| *v == 7);
        assert!(Arc::ptr_eq(&list.find(|v| *v == 7).expect("held"), &a));
        assert!(list.find(|v| *v == 8).is_none());
        // An equal value built meanwhile gives way to the one offered first.
        let b = list.share(Arc::new(7), |v| *v == 7);
        assert!(Arc::ptr_eq(&a, &b));
        drop((a, b));
        assert!(list.find(|v| *v == 7).is_none(), "nobody holds it any more");
    }
}
