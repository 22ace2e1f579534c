//! A small per-set cache of metric-dependent factorisations (e.g. the §7.2 eigendecompositions), keyed by the
//! metric matrix, so that repeated queries with the same metric (one trajectory, many samples) factor once.

use super::{GeometryError, Metric};
use std::sync::{Arc, RwLock};

/// How many metrics a set remembers (oldest evicted first).
const CAPACITY: usize = 8;

/// Factorisations of type `T` keyed by the metric (exact equality of n and R).
pub(crate) struct MetricCache<T> {
    entries: RwLock<Vec<Entry<T>>>,
}

/// (n, R, value).
type Entry<T> = (usize, Vec<f64>, Arc<T>);

impl<T> Default for MetricCache<T> {
    fn default() -> Self {
        Self {
            entries: RwLock::new(Vec::new()),
        }
    }
}

impl<T> MetricCache<T> {
    /// The cached value for `metric`, or `make()` stored and returned. Errors are not cached.
    pub fn get_or_try_insert(
        &self,
        metric: &Metric,
        make: impl FnOnce() -> Result<T, GeometryError>,
    ) -> Result<Arc<T>, GeometryError> {
        {
            let entries = self.entries.read().unwrap_or_else(|e| e.into_inner());
            if let Some((_, _, v)) = entries
                .iter()
                .find(|(n, R, _)| *n == metric.n && *R == metric.R)
            {
                return Ok(Arc::clone(v));
            }
        }
        let value = Arc::new(make()?);
        let mut entries = self.entries.write().unwrap_or_else(|e| e.into_inner());
        if entries.len() >= CAPACITY {
            entries.remove(0);
        }
        entries.push((metric.n, metric.R.clone(), Arc::clone(&value)));
        Ok(value)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn factors_once_per_metric_and_evicts() {
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
        for k in 0..CAPACITY {
            let mk = Metric {
                n: 1,
                R: vec![k as f64 + 2.0],
            };
            cache.get_or_try_insert(&mk, || Ok(k)).unwrap();
        }
        // The first entry was evicted: asking again calls `make`.
        let v = cache.get_or_try_insert(&m, || Ok(9)).unwrap();
        assert_eq!(*v, 9);
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
