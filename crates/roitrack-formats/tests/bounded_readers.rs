//! Every reader stays bounded on inputs it was not meant for: a 50 MB file without a line break, `/dev/zero`, a
//! binary file. Each is refused with an error naming the file (and the line where there is one), and a counting
//! allocator checks that no reader allocated more than 1 MiB on the way: refused by a limit, not after filling memory.
//! The inputs are generated here; nothing large is committed. Alone in its test binary, with one test, so that no
//! other test's allocations count.

use std::alloc::{GlobalAlloc, Layout, System};
use std::io::{Read, Write};
use std::path::Path;
use std::sync::atomic::{AtomicUsize, Ordering};

use roitrack_formats::{
    CameraFileOptions, FrameSource, FrameTiming, MeasurementReader, parse_target_csv, parse_tum,
    read_camera_file, read_camera_yaml, read_covariance_csv, read_diagnostics_csv, read_frame,
    read_target_csv, read_tum, read_twists_csv, write_frame_png,
};

/// The system allocator, counting the bytes held and their peak.
struct Counting;

static HELD: AtomicUsize = AtomicUsize::new(0);
static PEAK: AtomicUsize = AtomicUsize::new(0);

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        let held = HELD.fetch_add(layout.size(), Ordering::Relaxed) + layout.size();
        PEAK.fetch_max(held, Ordering::Relaxed);
        unsafe { System.alloc(layout) }
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        HELD.fetch_sub(layout.size(), Ordering::Relaxed);
        unsafe { System.dealloc(ptr, layout) }
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        if new_size > layout.size() {
            let held = HELD.fetch_add(new_size - layout.size(), Ordering::Relaxed) + new_size
                - layout.size();
            PEAK.fetch_max(held, Ordering::Relaxed);
        } else {
            HELD.fetch_sub(layout.size() - new_size, Ordering::Relaxed);
        }
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static ALLOCATOR: Counting = Counting;

/// The most a refused read may allocate (bytes): a line of 64 KiB and the readers' buffers, not the input.
const MAX_GROWTH_BYTES: usize = 1 << 20;

/// Runs `read`, checks that it failed with an error starting with `expected_start`, and that the peak of the bytes
/// held grew by less than [`MAX_GROWTH_BYTES`]; returns the error.
fn refused<T>(
    what: &str,
    expected_start: &str,
    read: impl FnOnce() -> Result<T, roitrack_formats::FormatError>,
) -> String {
    let before = HELD.load(Ordering::Relaxed);
    PEAK.store(before, Ordering::Relaxed);
    let error = match read() {
        Ok(_) => panic!("{what}: read without an error"),
        Err(e) => e.to_string(),
    };
    let growth = PEAK.load(Ordering::Relaxed) - before;
    assert!(
        growth < MAX_GROWTH_BYTES,
        "{what}: {growth} bytes allocated to refuse it ({error})"
    );
    assert!(
        error.starts_with(expected_start),
        "{what}: {error:?} does not start with {expected_start:?}"
    );
    error
}

/// A byte source of `len` bytes of `byte`, made on the fly.
struct Repeat {
    byte: u8,
    left: u64,
}

impl Read for Repeat {
    fn read(&mut self, out: &mut [u8]) -> std::io::Result<usize> {
        let n = out
            .len()
            .min(usize::try_from(self.left).unwrap_or(usize::MAX));
        out[..n].fill(self.byte);
        self.left -= n as u64;
        Ok(n)
    }
}

const FIFTY_MB: u64 = 50_000_000;

/// Writes `header` then `len` bytes of `byte` (no line break) to `path`, a megabyte at a time.
fn write_file(path: &Path, header: &[u8], byte: u8, len: u64) {
    let mut file = std::fs::File::create(path).unwrap();
    file.write_all(header).unwrap();
    std::io::copy(&mut Repeat { byte, left: len }, &mut file).unwrap();
}

#[test]
fn readers_refuse_unbounded_inputs_without_growing() {
    let dir = tempfile::tempdir().unwrap();
    let path = |name: &str| dir.path().join(name);
    let show = |name: &str| path(name).display().to_string();
    // Files of text digits without a line break: each reader's header, then 50 MB on one line.
    write_file(&path("m.csv"), b"t,id,u,v\n", b'1', FIFTY_MB);
    write_file(&path("t.csv"), b"", b'1', FIFTY_MB);
    write_file(&path("p.tum"), b"", b'1', FIFTY_MB);
    write_file(&path("w.csv"), b"t,vx,vy,vz,wx,wy,wz\n", b'1', FIFTY_MB);
    write_file(&path("d.csv"), b"", b'1', FIFTY_MB);
    write_file(&path("c.csv"), b"", b'1', FIFTY_MB);
    write_file(&path("camera.yaml"), b"", b'a', FIFTY_MB);
    write_file(&path("small.yaml"), b"", b'a', 900_000);
    write_file(&path("frame.png"), b"", b'1', FIFTY_MB);
    write_file(&path("times.csv"), b"t\n", b'1', 10_000_000);
    let mut bag = b"\x89MCAP0\r\n".to_vec();
    bag.extend([0u8; 100]);
    std::fs::write(path("bag.yaml"), &bag).unwrap();

    let line_2 = |name: &str| format!("{}:2: line 2 is longer than 65536 bytes", show(name));
    let line_1 = |name: &str| format!("{}:1: line 1 is longer than 65536 bytes", show(name));
    refused("measurements", &line_2("m.csv"), || {
        MeasurementReader::open(path("m.csv"))?.collect::<Result<Vec<_>, _>>()
    });
    refused(
        "measurements by a reader",
        "gen.csv:2: line 2 is longer",
        || {
            let source = std::io::Cursor::new(b"t,id,u,v\n".to_vec()).chain(Repeat {
                byte: b'1',
                left: FIFTY_MB,
            });
            MeasurementReader::from_reader(source, "gen.csv")?.collect::<Result<Vec<_>, _>>()
        },
    );
    // The target file's size is known beforehand: refused before a byte is read.
    let e = refused("target", &show("t.csv"), || read_target_csv(path("t.csv")));
    assert!(e.contains("is at most 16 MiB"), "{e}");
    refused("target by a reader", "gen.csv:1: line 1 is longer", || {
        parse_target_csv(
            Repeat {
                byte: b'1',
                left: FIFTY_MB,
            },
            "gen.csv",
        )
    });
    refused("poses", &line_1("p.tum"), || read_tum(path("p.tum")));
    refused("poses by a reader", "gen.tum:1: line 1 is longer", || {
        parse_tum(
            Repeat {
                byte: b'1',
                left: FIFTY_MB,
            },
            "gen.tum",
        )
    });
    refused("twists", &line_2("w.csv"), || {
        read_twists_csv(path("w.csv"))
    });
    refused("diagnostics", &line_1("d.csv"), || {
        read_diagnostics_csv(path("d.csv"))
    });
    refused("covariance", &line_1("c.csv"), || {
        read_covariance_csv(path("c.csv"))
    });
    let options = CameraFileOptions::default();
    let e = refused("camera", &show("camera.yaml"), || {
        read_camera_file(path("camera.yaml"), &options)
    });
    assert!(e.contains("is at most 1 MiB"), "{e}");
    refused("camera without line breaks", &line_1("small.yaml"), || {
        read_camera_file(path("small.yaml"), &options)
    });
    refused(
        "ROS camera without line breaks",
        &line_1("small.yaml"),
        || read_camera_yaml(path("small.yaml")),
    );
    let e = refused("bag as camera", &show("bag.yaml"), || {
        read_camera_file(path("bag.yaml"), &options)
    });
    assert!(e.contains("an MCAP file (a ROS 2 bag)"), "{e}");
    let e = refused("image", &show("frame.png"), || {
        read_frame(path("frame.png"))
    });
    assert!(e.contains("not a PNG image"), "{e}");

    // Timestamps: a sequence of two frames, and a timestamps file of 10 MB on its second line.
    let frames = path("frames");
    std::fs::create_dir(&frames).unwrap();
    for k in 0..2 {
        let frame = roitrack_image::Frame::new(8, 6, 8);
        write_frame_png(frames.join(format!("f{k}.png")), &frame).unwrap();
    }
    let timing = FrameTiming {
        timestamps: Some(path("times.csv")),
        ..FrameTiming::default()
    };
    refused("timestamps", &line_2("times.csv"), || {
        FrameSource::open(&frames, &timing)
    });

    // The devices a careless user may name: no size to check, so the readers' own limits stop them.
    if Path::new("/dev/zero").exists() {
        let zero = Path::new("/dev/zero");
        let e = refused("/dev/zero as a camera", "/dev/zero:1: ", || {
            read_camera_file(zero, &options)
        });
        assert!(e.contains("a NUL byte"), "{e}");
        refused("/dev/zero as measurements", "/dev/zero:1: line 1", || {
            MeasurementReader::open(zero)?.collect::<Result<Vec<_>, _>>()
        });
        refused("/dev/zero as a target", "/dev/zero:1: line 1", || {
            read_target_csv(zero)
        });
        refused("/dev/zero as poses", "/dev/zero:1: line 1", || {
            read_tum(zero)
        });
        refused("/dev/zero as an image", "/dev/zero: ", || read_frame(zero));
        let timing = FrameTiming {
            timestamps: Some(zero.into()),
            ..FrameTiming::default()
        };
        refused("/dev/zero as timestamps", "/dev/zero:1: line 1", || {
            FrameSource::open(&frames, &timing)
        });
    }
}
