//! The streaming readers read huge inputs in constant memory: a measurements CSV of 3 million rows (about 100 MB) and
//! a ROI recording of 100,000 ROIs (about 160 MB), generated on the fly by a `Read` so that no disk is needed, leave
//! the process's peak resident memory where a few thousand rows put it. Alone in its test binary, so that no other
//! test's allocations move the peak.

use std::io::Read;

use roitrack_formats::{MeasurementReader, ROI_RECORDING_MAGIC, RoiRecordingReader};

/// A byte source that produces `header` then `count` chunks from `chunk(k)`, one at a time.
struct Generated<F: FnMut(u64, &mut Vec<u8>)> {
    chunk: F,
    next: u64,
    count: u64,
    buffer: Vec<u8>,
    at: usize,
}

impl<F: FnMut(u64, &mut Vec<u8>)> Generated<F> {
    fn new(header: &[u8], count: u64, chunk: F) -> Self {
        Self {
            chunk,
            next: 0,
            count,
            buffer: header.to_vec(),
            at: 0,
        }
    }
}

impl<F: FnMut(u64, &mut Vec<u8>)> Read for Generated<F> {
    fn read(&mut self, out: &mut [u8]) -> std::io::Result<usize> {
        if self.at == self.buffer.len() {
            if self.next == self.count {
                return Ok(0);
            }
            self.buffer.clear();
            self.at = 0;
            (self.chunk)(self.next, &mut self.buffer);
            self.next += 1;
        }
        let n = out.len().min(self.buffer.len() - self.at);
        out[..n].copy_from_slice(&self.buffer[self.at..self.at + n]);
        self.at += n;
        Ok(n)
    }
}

/// Peak resident memory of this process (MiB), from /proc (Linux); None elsewhere.
fn peak_rss_mib() -> Option<f64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kib: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib / 1024.0)
}

fn measurements(rows: u64) -> impl Read {
    Generated::new(b"t,id,u,v\n", rows, |k, out| {
        let line = format!(
            "{:.6},{},{:.4},{:.4}\n",
            k as f64 * 250e-6,
            k % 16,
            500.0 + (k % 97) as f64 * 0.25,
            480.0 - (k % 89) as f64 * 0.5
        );
        out.extend_from_slice(line.as_bytes());
    })
}

fn recording(records: u64) -> impl Read {
    const SIDE: u32 = 40;
    Generated::new(ROI_RECORDING_MAGIC, records, |k, out| {
        out.extend_from_slice(&(k as f64 * 250e-6).to_le_bytes());
        for v in [(k % 16) as u32, 100, 200, SIDE, SIDE] {
            out.extend_from_slice(&v.to_le_bytes());
        }
        out.push(8);
        out.extend((0..SIDE * SIDE).map(|i| ((i as u64 + k) % 251) as u8));
    })
}

#[test]
fn huge_inputs_are_read_in_constant_memory() {
    // Warm-up: a small input of each kind sets the baseline peak.
    let small = MeasurementReader::from_reader(measurements(5_000), "small.csv")
        .unwrap()
        .with_known_ids(0..16)
        .map(|m| m.unwrap().t_s)
        .sum::<f64>();
    let small_rois = RoiRecordingReader::from_reader(recording(2_000), "small.bin")
        .unwrap()
        .map(|r| r.unwrap().pixels.len())
        .sum::<usize>();
    assert!(small > 0.0 && small_rois == 2_000 * 1600);
    let Some(baseline_mib) = peak_rss_mib() else {
        eprintln!("no /proc/self/status: peak memory not checked");
        return;
    };

    let (mut count, mut last_t) = (0u64, -1.0);
    for m in MeasurementReader::from_reader(measurements(3_000_000), "huge.csv")
        .unwrap()
        .with_known_ids(0..16)
    {
        let m = m.unwrap();
        assert!(m.t_s >= last_t);
        last_t = m.t_s;
        count += 1;
    }
    assert_eq!(count, 3_000_000);
    let mut rois = 0u64;
    for r in RoiRecordingReader::from_reader(recording(100_000), "huge.bin").unwrap() {
        assert_eq!(r.unwrap().pixels.len(), 1600);
        rois += 1;
    }
    assert_eq!(rois, 100_000);

    let growth_mib = peak_rss_mib().unwrap() - baseline_mib;
    // 100 MB of CSV and 160 MB of ROIs went through: the peak may move by buffer sizes, not by the inputs.
    assert!(
        growth_mib < 4.0,
        "peak resident memory grew by {growth_mib:.1} MiB reading huge inputs"
    );
}
