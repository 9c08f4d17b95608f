//! A process-wide list of values derived from map contents, shared by every holder: robots of a
//! team (and trials run side by side) that hold the same map build such a value once. Entries
//! are weak, so a value lives only as long as someone holds it.

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

#[cfg(test)]
mod tests {
    use super::*;

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
