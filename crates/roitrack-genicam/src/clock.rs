//! The offset between a camera's clock and the host's, estimated from the buffers' device timestamps and the host
//! times they arrived at.
//!
//! A buffer reaches the host some time after its exposure (readout, transfer, the driver), never before, so for every
//! buffer `device - host_arrival = offset - latency` with `latency >= 0`: the largest value over recent buffers is the
//! offset less the smallest latency, a figure that jitter does not move. It is kept over two blocks of buffers, so
//! that a drift between the clocks is followed within a block.

/// Running estimate of `device clock - host clock` (s).
///
/// ```
/// use roitrack_genicam::ClockOffset;
/// let mut clock = ClockOffset::new(4);
/// // The device clock is 100 s ahead; buffers arrive 1 to 3 ms after their exposure.
/// for (k, latency_s) in [0.003, 0.001, 0.002, 0.0015].iter().enumerate() {
///     let exposed_host_s = k as f64 * 0.01;
///     clock.update(exposed_host_s + 100.0, exposed_host_s + latency_s);
/// }
/// let offset_s = clock.offset_s().unwrap();
/// assert!((offset_s - (100.0 - 0.001)).abs() < 1e-9);
/// // A device time on the host's clock (with the smallest latency taken as 0).
/// assert!((clock.to_host_s(100.05).unwrap() - 0.051).abs() < 1e-9);
/// ```
#[derive(Debug, Clone)]
pub struct ClockOffset {
    block_len: usize,
    in_block: usize,
    current_max_s: f64,
    previous_max_s: f64,
    samples: u64,
    first_s: Option<f64>,
    /// Sum and sum of squares of `estimate - sample` (the latency above the smallest), for the spread.
    latency_sum_s: f64,
    latency_sq_sum_s2: f64,
}

impl ClockOffset {
    /// An estimator over blocks of `block_len` buffers (at least 1).
    pub fn new(block_len: usize) -> Self {
        Self {
            block_len: block_len.max(1),
            in_block: 0,
            current_max_s: f64::NEG_INFINITY,
            previous_max_s: f64::NEG_INFINITY,
            samples: 0,
            first_s: None,
            latency_sum_s: 0.0,
            latency_sq_sum_s2: 0.0,
        }
    }

    /// Takes one buffer: its device timestamp and the host time it arrived at (s, each on its own clock). Non-finite
    /// times are ignored.
    pub fn update(&mut self, device_s: f64, host_arrival_s: f64) {
        let sample = device_s - host_arrival_s;
        if !sample.is_finite() {
            return;
        }
        self.current_max_s = self.current_max_s.max(sample);
        self.in_block += 1;
        self.samples += 1;
        if self.in_block >= self.block_len {
            self.previous_max_s = self.current_max_s;
            self.current_max_s = f64::NEG_INFINITY;
            self.in_block = 0;
            // The first estimate over a whole block: the reference of the drift (the very first buffers, a large
            // full frame among them, may have come late).
            self.first_s.get_or_insert(self.previous_max_s);
        }
        let estimate = self.current_max_s.max(self.previous_max_s);
        let latency = estimate - sample;
        self.latency_sum_s += latency;
        self.latency_sq_sum_s2 += latency * latency;
    }

    /// The current estimate of `device - host` (s), once a buffer was seen.
    pub fn offset_s(&self) -> Option<f64> {
        let estimate = self.current_max_s.max(self.previous_max_s);
        estimate.is_finite().then_some(estimate)
    }

    /// A device time on the host's clock (s).
    pub fn to_host_s(&self, device_s: f64) -> Option<f64> {
        self.offset_s().map(|offset| device_s - offset)
    }

    /// How far the estimate moved since the end of the first block of buffers (s): the clocks' drift over the run,
    /// plus any change of the smallest latency; `None` before a block is complete.
    pub fn change_s(&self) -> Option<f64> {
        Some(self.offset_s()? - self.first_s?)
    }

    /// Buffers seen.
    pub fn samples(&self) -> u64 {
        self.samples
    }

    /// Mean and standard deviation of each buffer's latency above the smallest (s): the jitter of the arrival times.
    pub fn jitter_s(&self) -> Option<(f64, f64)> {
        if self.samples == 0 {
            return None;
        }
        let n = self.samples as f64;
        let mean = self.latency_sum_s / n;
        Some((
            mean,
            (self.latency_sq_sum_s2 / n - mean * mean).max(0.0).sqrt(),
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn follows_a_drifting_clock_within_two_blocks() {
        let mut clock = ClockOffset::new(100);
        // 50 ppm of drift, latencies 0.2-1.2 ms.
        for k in 0..10_000 {
            let host_s = k as f64 * 1e-3;
            let device_s = 5.0 + host_s * (1.0 + 50e-6);
            let latency_s = 2e-4 + 1e-3 * ((k * 7919) % 101) as f64 / 100.0;
            clock.update(device_s, host_s + latency_s);
        }
        let truth_s = 5.0 + 10.0 * 50e-6;
        let offset_s = clock.offset_s().unwrap();
        // Within the smallest latency plus the drift over two blocks (200 ms at 50 ppm: 10 us).
        assert!((truth_s - 2e-4 - offset_s).abs() < 2e-5, "{offset_s}");
        assert!(clock.change_s().unwrap() > 4e-4);
        assert_eq!(clock.samples(), 10_000);
    }

    #[test]
    fn no_buffer_no_estimate_and_nan_is_ignored() {
        let mut clock = ClockOffset::new(8);
        assert_eq!(clock.offset_s(), None);
        clock.update(f64::NAN, 1.0);
        assert_eq!((clock.offset_s(), clock.samples()), (None, 0));
        assert!(clock.jitter_s().is_none());
    }
}
