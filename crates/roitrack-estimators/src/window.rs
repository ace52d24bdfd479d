//! The measurement window: the newest undistorted centroids, kept without allocating once built.

use nalgebra::Vector2;

use super::Observation;

/// Which measurements a control step uses.
///
/// ```
/// use roitrack_estimators::{TrackerConfig, WindowMode};
/// let config = TrackerConfig { window: WindowMode::Last(32), ..TrackerConfig::default() };
/// assert!(config.validate().is_ok());
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum WindowMode {
    /// The newest measurement of each point (the paper).
    NewestPerPoint,
    /// The last `n` measurements.
    Last(usize),
}

/// A ring buffer of the last `capacity` observations plus the newest observation of each point.
#[derive(Debug, Clone)]
pub(crate) struct ObservationWindow {
    ring: Vec<Observation>,
    /// Index where the next observation goes.
    head: usize,
    len: usize,
    newest_by_point: Vec<Option<Observation>>,
    points_seen: usize,
}

impl ObservationWindow {
    pub fn new(point_count: usize, capacity: usize) -> Self {
        let capacity = capacity.max(1);
        Self {
            ring: vec![
                Observation {
                    t_s: 0.0,
                    point_index: 0,
                    ideal_px: Vector2::zeros(),
                };
                capacity
            ],
            head: 0,
            len: 0,
            newest_by_point: vec![None; point_count],
            points_seen: 0,
        }
    }

    pub fn clear(&mut self) {
        self.head = 0;
        self.len = 0;
        self.newest_by_point.iter_mut().for_each(|o| *o = None);
        self.points_seen = 0;
    }

    pub fn push(&mut self, obs: Observation) {
        let capacity = self.ring.len();
        self.ring[self.head] = obs;
        self.head = (self.head + 1) % capacity;
        self.len = (self.len + 1).min(capacity);
        if self.newest_by_point[obs.point_index].replace(obs).is_none() {
            self.points_seen += 1;
        }
    }

    /// Number of observations held in the ring.
    pub fn len(&self) -> usize {
        self.len
    }

    /// Number of distinct points with at least one observation.
    pub fn points_seen(&self) -> usize {
        self.points_seen
    }

    /// The newest observation of each point seen.
    pub fn newest_per_point(&self) -> impl Iterator<Item = &Observation> {
        self.newest_by_point.iter().flatten()
    }

    /// The last `n` observations (fewer if fewer are held), newest first.
    pub fn last(&self, n: usize) -> impl Iterator<Item = &Observation> {
        let capacity = self.ring.len();
        (0..n.min(self.len)).map(move |k| &self.ring[(self.head + capacity - 1 - k) % capacity])
    }

    /// The cycle `back` cycles before the newest: the (`back` + 1)-th newest observation of every point seen, newest
    /// first (`back` = 0: the newest of each); `None` unless every point seen has that many in the ring.
    pub fn cycle(&self, back: usize) -> Option<Vec<Observation>> {
        let mut seen = vec![0usize; self.newest_by_point.len()];
        let mut cycle = Vec::with_capacity(self.points_seen);
        for o in self.last(self.len) {
            let count = &mut seen[o.point_index];
            *count += 1;
            if *count == back + 1 {
                cycle.push(*o);
            }
        }
        (cycle.len() == self.points_seen && self.points_seen > 0).then_some(cycle)
    }

    /// The observations selected by `mode`.
    pub fn select(&self, mode: WindowMode) -> impl Iterator<Item = &Observation> {
        let (newest, last) = match mode {
            WindowMode::NewestPerPoint => (Some(self.newest_per_point()), None),
            WindowMode::Last(n) => (None, Some(self.last(n))),
        };
        newest
            .into_iter()
            .flatten()
            .chain(last.into_iter().flatten())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn obs(t: f64, i: usize) -> Observation {
        Observation {
            t_s: t,
            point_index: i,
            ideal_px: Vector2::new(t, i as f64),
        }
    }

    #[test]
    fn cycles_back_from_the_newest() {
        let mut w = ObservationWindow::new(3, 10);
        for k in 0..7 {
            w.push(obs(k as f64, k % 3));
        }
        // Points 0, 1, 2 measured at 0-6 s: point 0 at 0, 3, 6; point 1 at 1, 4; point 2 at 2, 5.
        let times = |c: Vec<Observation>| c.iter().map(|o| o.t_s).collect::<Vec<_>>();
        assert_eq!(times(w.cycle(0).unwrap()), [6.0, 5.0, 4.0]);
        assert_eq!(times(w.cycle(1).unwrap()), [3.0, 2.0, 1.0]);
        assert_eq!(w.cycle(2), None);
    }

    #[test]
    fn keeps_the_newest() {
        let mut w = ObservationWindow::new(3, 4);
        for k in 0..7 {
            w.push(obs(k as f64, k % 3));
        }
        let last: Vec<f64> = w.last(10).map(|o| o.t_s).collect();
        assert_eq!(last, vec![6.0, 5.0, 4.0, 3.0]);
        let mut newest: Vec<f64> = w.newest_per_point().map(|o| o.t_s).collect();
        newest.sort_by(f64::total_cmp);
        assert_eq!(newest, vec![4.0, 5.0, 6.0]);
        assert_eq!(w.select(WindowMode::Last(2)).count(), 2);
        assert_eq!(w.select(WindowMode::NewestPerPoint).count(), 3);
        w.clear();
        assert_eq!(w.len(), 0);
        assert_eq!(w.points_seen(), 0);
    }
}
