//! Bounded series of timings (frame, prepare and edit-to-mesh milliseconds) and their
//! summary, for the window's status line and state dump or any face that times itself.

/// The latest values of one measurement, at most a fixed number (the oldest leave first).
#[derive(Clone, Debug)]
pub struct Samples {
    values: Vec<f64>,
    max: usize,
}

/// Mean, median, 95th percentile and maximum of some samples (percentiles are the nearest
/// sample's value).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Summary {
    /// Samples summarised.
    pub n: usize,
    /// Their mean.
    pub mean: f64,
    /// The median.
    pub p50: f64,
    /// The 95th percentile.
    pub p95: f64,
    /// The largest.
    pub max: f64,
}

impl Samples {
    /// No samples yet; keeps the latest `max`.
    pub fn new(max: usize) -> Samples {
        assert!(max > 0, "a series keeps at least one sample");
        Samples {
            values: Vec::new(),
            max,
        }
    }

    /// Adds `value`, dropping the oldest when full.
    pub fn push(&mut self, value: f64) {
        if self.values.len() >= self.max {
            self.values.remove(0);
        }
        self.values.push(value);
    }

    /// The samples kept, oldest first.
    pub fn values(&self) -> &[f64] {
        &self.values
    }

    /// The latest sample.
    pub fn last(&self) -> Option<f64> {
        self.values.last().copied()
    }

    /// The summary, or `None` with no samples.
    pub fn summary(&self) -> Option<Summary> {
        if self.values.is_empty() {
            return None;
        }
        let mut sorted = self.values.clone();
        sorted.sort_by(f64::total_cmp);
        let at = |q: f64| sorted[((sorted.len() - 1) as f64 * q).round() as usize];
        Some(Summary {
            n: sorted.len(),
            mean: sorted.iter().sum::<f64>() / sorted.len() as f64,
            p50: at(0.5),
            p95: at(0.95),
            max: at(1.0),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_full_series_drops_its_oldest_and_summarises_what_it_keeps() {
        let mut samples = Samples::new(3);
        assert_eq!(samples.summary(), None);
        for v in [9.0, 4.0, 1.0, 2.0] {
            samples.push(v);
        }
        assert_eq!(samples.values(), &[4.0, 1.0, 2.0]);
        assert_eq!(samples.last(), Some(2.0));
        let s = samples.summary().unwrap();
        assert_eq!(s.n, 3);
        assert_eq!(s.mean, 7.0 / 3.0);
        assert_eq!((s.p50, s.p95, s.max), (2.0, 4.0, 4.0));
    }
}
