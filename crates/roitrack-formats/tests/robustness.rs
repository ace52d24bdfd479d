//! No reader panics on any input: valid files mutated byte by byte, truncated anywhere, or replaced by noise give an
//! `Ok` or a `FormatError` naming the file.

use roitrack_core::{CameraModel, PinholeIntrinsics, PlumbBob, Target};
use roitrack_formats::{
    MeasurementReader, camera_yaml_string, parse_camera_yaml, parse_target_csv, parse_tum,
    parse_twists_csv, target_csv_string,
};

/// A small deterministic generator (xorshift64*), enough to pick mutations.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_f491_4f6c_dd1d)
    }

    fn below(&mut self, n: usize) -> usize {
        (self.next() % n as u64) as usize
    }
}

/// Bytes that are likely to matter to the parsers.
const INTERESTING: &[u8] = b",.:-+eE0123456789 \t\n\r#[]{}'\"\\naNIf\xff\x00";

/// Mutations of `valid`: replaced, inserted and deleted bytes, and truncations.
fn mutations(valid: &[u8], count: usize, seed: u64) -> Vec<Vec<u8>> {
    let mut rng = Rng(seed);
    let mut out: Vec<Vec<u8>> = (0..=valid.len()).map(|n| valid[..n].to_vec()).collect();
    for _ in 0..count {
        let mut bytes = valid.to_vec();
        for _ in 0..1 + rng.below(3) {
            let at = rng.below(bytes.len().max(1));
            let b = INTERESTING[rng.below(INTERESTING.len())];
            match rng.below(3) {
                0 if at < bytes.len() => bytes[at] = b,
                1 => bytes.insert(at.min(bytes.len()), b),
                _ if at < bytes.len() => {
                    bytes.remove(at);
                }
                _ => {}
            }
        }
        out.push(bytes);
    }
    out.push((0..500).map(|_| rng.next() as u8).collect());
    out
}

fn check<T>(result: Result<T, roitrack_formats::FormatError>, name: &str) {
    if let Err(e) = result {
        assert!(e.to_string().starts_with(name), "{e}");
    }
}

#[test]
fn camera_yaml_never_panics() {
    let camera = CameraModel::new(
        "cam",
        640,
        480,
        PinholeIntrinsics {
            fx_px: 500.5,
            fy_px: 501.25,
            skew_px: 0.5,
            cx_px: 320.0,
            cy_px: 240.0,
        },
        PlumbBob::from_coefficients([-0.2, 0.05, 1e-3, -1e-3, 0.01]),
    )
    .unwrap();
    let valid = camera_yaml_string(&camera);
    for bytes in mutations(valid.as_bytes(), 3000, 1) {
        let text = String::from_utf8_lossy(&bytes);
        check(parse_camera_yaml(&text, "c.yaml"), "c.yaml");
    }
}

#[test]
fn csv_and_tum_readers_never_panic() {
    let target = target_csv_string(&Target::grid4x4());
    for bytes in mutations(target.as_bytes(), 2000, 2) {
        check(parse_target_csv(&bytes[..], "t.csv"), "t.csv");
    }
    let measurements = "t,id,u,v\n0,1,100.5,200.25\n0.01,2,101,-3e2\n0.02,3,1,2\n";
    for bytes in mutations(measurements.as_bytes(), 2000, 3) {
        let result = MeasurementReader::from_reader(&bytes[..], "m.csv")
            .and_then(|r| r.with_known_ids(0..4).collect::<Result<Vec<_>, _>>());
        check(result, "m.csv");
    }
    let tum = "# t tx ty tz qx qy qz qw\n0 0.1 0.2 0.5 0 0 0 1\n0.01 0.1 0.2 0.5 0 0 0.6 0.8\n";
    for bytes in mutations(tum.as_bytes(), 2000, 4) {
        check(parse_tum(&bytes[..], "p.tum"), "p.tum");
    }
    let twists = "t,vx,vy,vz,wx,wy,wz\n0,1,2,3,4,5,6\n0.01,1,2,3,4,5,6e-3\n";
    for bytes in mutations(twists.as_bytes(), 2000, 5) {
        check(parse_twists_csv(&bytes[..], "w.csv"), "w.csv");
    }
}
