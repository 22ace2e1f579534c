//! A small per-set cache of metric-dependent factorisations (e.g. the §7.2 eigendecompositions), keyed by the
//! metric matrix, so that repeated queries with the same metric (one trajectory, many samples) factor once.
//!
//! The first [`CAPACITY`] metrics a set meets fill write-once slots that a hit reads with one atomic load
//! and no write: the verifier's threads ask the same sets millions of times, and a lock or a reference
//! count taken per query made every hit write the same cache line from both cores. Metrics past those
//! go to a small list behind a lock, oldest evicted first.

use super::{GeometryError, Metric};
use std::sync::{Arc, OnceLock, RwLock};

/// How many metrics a set keeps in its lock-free slots, and how many more in its list.
const CAPACITY: usize = 8;

/// Factorisations of type `T` keyed by the metric (exact equality of n and R).
pub(crate) struct MetricCache<T> {
    slots: [OnceLock<Entry<T>>; CAPACITY],
    overflow: RwLock<Vec<Entry<T>>>,
}

/// (n, R, value).
type Entry<T> = (usize, Vec<f64>, Arc<T>);

impl<T> Default for MetricCache<T> {
    fn default() -> Self {
        Self {
            slots: std::array::from_fn(|_| OnceLock::new()),
            overflow: RwLock::new(Vec::new()),
        }
    }
}

/// A cached value: borrowed from its slot, or shared from the list.
pub enum Cached<'a, T> {
    Slot(&'a T),
    Shared(Arc<T>),
}

impl<T> std::ops::Deref for Cached<'_, T> {
    type Target = T;
    fn deref(&self) -> &T {
        match self {
            Cached::Slot(t) => t,
            Cached::Shared(t) => t,
        }
    }
}

fn same<T>(e: &Entry<T>, metric: &Metric) -> bool {
    e.0 == metric.n && e.1 == metric.R
}

impl<T> MetricCache<T> {
    /// The cached value for `metric`, or `make()` stored and returned. Errors are not cached.
    pub fn get_or_try_insert(
        &self,
        metric: &Metric,
        make: impl FnOnce() -> Result<T, GeometryError>,
    ) -> Result<Cached<'_, T>, GeometryError> {
        for slot in &self.slots {
            match slot.get() {
                Some(e) if same(e, metric) => return Ok(Cached::Slot(&e.2)),
                Some(_) => {}
                None => break,
            }
        }
        {
            let list = self.overflow.read().unwrap_or_else(|e| e.into_inner());
            if let Some(e) = list.iter().find(|e| same(e, metric)) {
                return Ok(Cached::Shared(Arc::clone(&e.2)));
            }
        }
        let value = Arc::new(make()?);
        // The first free slot; a slot another thread filled meanwhile is skipped (or is this metric's).
        for slot in &self.slots {
            let _ = slot.set((metric.n, metric.R.clone(), Arc::clone(&value)));
            if let Some(e) = slot.get().filter(|e| same(e, metric)) {
                return Ok(Cached::Slot(&e.2));
            }
        }
        let mut list = self.overflow.write().unwrap_or_else(|e| e.into_inner());
        if list.len() >= CAPACITY {
            list.remove(0);
        }
        list.push((metric.n, metric.R.clone(), Arc::clone(&value)));
        Ok(Cached::Shared(value))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn factors_once_per_metric_keeps_its_slots_and_evicts_the_list() {
        let cache = MetricCache::<usize>::default();
        let mut calls = 0;
        let m = Metric::euclidean(2);
        for _ in 0..3 {
            let v = cache
                .get_or_try_insert(&m, || {
                    calls += 1;
                    Ok(7)
                })
                .unwrap();
            assert_eq!(*v, 7);
        }
        assert_eq!(calls, 1);
        // The slots keep the first CAPACITY metrics for good; the list keeps CAPACITY more, oldest
        // evicted first.
        let mk = |k: usize| Metric {
            n: 1,
            R: vec![k as f64 + 2.0],
        };
        for k in 0..2 * CAPACITY {
            cache.get_or_try_insert(&mk(k), || Ok(k)).unwrap();
        }
        assert_eq!(
            *cache.get_or_try_insert(&m, || Ok(9)).unwrap(),
            7,
            "in a slot"
        );
        assert!(matches!(
            cache.get_or_try_insert(&mk(0), || Ok(99)).unwrap(),
            Cached::Slot(_)
        ));
        // mk(CAPACITY - 1) was the first in the list; CAPACITY more came after it, so it was evicted.
        let v = cache
            .get_or_try_insert(&mk(CAPACITY - 1), || Ok(99))
            .unwrap();
        assert_eq!(*v, 99);
        assert!(matches!(v, Cached::Shared(_)));
        let w = cache
            .get_or_try_insert(&mk(2 * CAPACITY - 1), || Ok(98))
            .unwrap();
        assert_eq!(*w, 2 * CAPACITY - 1, "still in the list");
        // Errors are not stored.
        let bad = Metric {
            n: 1,
            R: vec![-1.0],
        };
        assert!(cache
            .get_or_try_insert(&bad, || Err(GeometryError::EmptyUnion))
            .is_err());
        assert_eq!(*cache.get_or_try_insert(&bad, || Ok(3)).unwrap(), 3);
    }
}
