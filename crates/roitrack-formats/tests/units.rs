//! Files in the wrong units are refused with the option that reads them; saying the unit reads them.

use roitrack_formats::{
    LengthUnit, MeasurementReader, TimeUnit, TimedMeasurements, parse_target_csv_in,
};

const GRID_MM: &str = "id,x,y,z,diameter\n0,0,0,0,6\n1,60,0,0,6\n2,0,60,0,6\n3,60,60,0.5,6\n";

#[test]
fn target_units() {
    let e = parse_target_csv_in(GRID_MM.as_bytes(), "t.csv", None)
        .unwrap_err()
        .to_string();
    assert!(
        e.starts_with("t.csv: field 'x, y, z': its points span 84.854 m"),
        "{e}"
    );
    assert!(
        e.contains("millimetres")
            && e.contains("--target-units mm")
            && e.contains("--target-units m "),
        "{e}"
    );
    let mm = parse_target_csv_in(GRID_MM.as_bytes(), "t.csv", Some(LengthUnit::Mm)).unwrap();
    assert_eq!(mm.points()[3].point_in_obj_m.z, 0.0005);
    assert_eq!(mm.points()[3].diameter_m, Some(0.006));
    let cm_text = "id,x,y,z,diameter\n0,0,0,0,0.6\n1,6,0,0,0.6\n2,0,6,0,0.6\n3,6,6,0,0.6\n";
    let e = parse_target_csv_in(cm_text.as_bytes(), "t.csv", None)
        .unwrap_err()
        .to_string();
    assert!(e.contains("--target-units cm"), "{e}");
    let cm = parse_target_csv_in(cm_text.as_bytes(), "t.csv", Some(LengthUnit::Cm)).unwrap();
    assert!((cm.points()[1].point_in_obj_m.x - 0.06).abs() < 1e-15);
    // Only the blobs too big: named by their field.
    let blobs = "id,x,y,z,diameter\n0,0,0,0,6\n1,0.06,0,0,6\n2,0,0.06,0,6\n3,0.06,0.06,0,6\n";
    let e = parse_target_csv_in(blobs.as_bytes(), "t.csv", None)
        .unwrap_err()
        .to_string();
    assert!(
        e.starts_with("t.csv: field 'diameter': a blob is 6.000 m across"),
        "{e}"
    );
    // A big target in metres, said so.
    let big = "id,x,y,z\n0,0,0,0\n1,3,0,0\n2,0,3,0\n3,3,3,0\n";
    assert!(parse_target_csv_in(big.as_bytes(), "t.csv", None).is_err());
    assert!(parse_target_csv_in(big.as_bytes(), "t.csv", Some(LengthUnit::M)).is_ok());
}

fn timed(text: &str, units: Option<TimeUnit>) -> Result<Vec<f64>, String> {
    let reader = MeasurementReader::from_reader(text.as_bytes(), "m.csv").unwrap();
    TimedMeasurements::new(reader, units)
        .map(|m| m.map(|m| m.t_s))
        .collect::<Result<Vec<_>, _>>()
        .map_err(|e| e.to_string())
}

/// `n` rows `step` apart from `start`, 16 ids in turn.
fn rows(start: f64, step: f64, n: usize) -> String {
    let mut text = String::from("t,id,u,v\n");
    for k in 0..n {
        text.push_str(&format!("{},{},500,500\n", start + step * k as f64, k % 16));
    }
    text
}

#[test]
fn time_units() {
    // 4 kHz in seconds, milliseconds, microseconds, nanoseconds.
    assert_eq!(timed(&rows(0.0, 2.5e-4, 3000), None).unwrap().len(), 3000);
    for (step, unit, name) in [
        (0.25, TimeUnit::Ms, "ms"),
        (250.0, TimeUnit::Us, "us"),
        (250e3, TimeUnit::Ns, "ns"),
    ] {
        let text = rows(0.0, step, 3000);
        let e = timed(&text, None).unwrap_err();
        assert!(
            e.starts_with("m.csv:3: field 't': successive measurements are"),
            "{e}"
        );
        assert!(
            e.contains(&format!("--time-units {name} ")) && e.contains("4.000 kHz"),
            "{e}"
        );
        let t = timed(&text, Some(unit)).unwrap();
        assert_eq!(t.len(), 3000);
        assert!((t[2999] - 2999.0 * 2.5e-4).abs() < 1e-12, "{}", t[2999]);
    }
    // A global-shutter camera at 30 frames/s, 16 blobs a frame, in milliseconds.
    let mut text = String::from("t,id,u,v\n");
    for frame in 0..40 {
        for id in 0..16 {
            text.push_str(&format!("{},{id},500,500\n", frame as f64 * 33.3));
        }
    }
    assert!(timed(&text, None).unwrap_err().contains("--time-units ms"));
    // Unix times in nanoseconds, seconds (accepted) and milliseconds.
    let e = timed(&rows(1.764e18, 2.5e5, 10), None).unwrap_err();
    assert!(
        e.starts_with("m.csv:2: field 't': ") && e.contains("--time-units ns"),
        "{e}"
    );
    assert!(timed(&rows(1.764e9, 2.5e-4, 10), None).is_ok());
    assert!(
        timed(&rows(1.764e12, 0.25, 10), None)
            .unwrap_err()
            .contains("--time-units ms")
    );
    // Slow but real, said so.
    assert!(timed(&rows(0.0, 0.5, 10), None).is_err());
    assert_eq!(
        timed(&rows(0.0, 0.5, 10), Some(TimeUnit::S)).unwrap().len(),
        10
    );
    // An error among the rows read ahead comes after the rows before it, with its own line.
    let mut text = rows(0.0, 2.5e-4, 10);
    text.push_str("oops,1,1,1\n");
    let reader = MeasurementReader::from_reader(text.as_bytes(), "m.csv").unwrap();
    let items: Vec<_> = TimedMeasurements::new(reader, None).collect();
    assert_eq!(items.len(), 11);
    assert!(
        items[10]
            .as_ref()
            .unwrap_err()
            .to_string()
            .starts_with("m.csv:12: field 't'")
    );
}

#[test]
fn centroids_off_the_image_name_line_and_field() {
    let text = "t,id,u,v\n0,0,500,500\n0.001,1,1023.5,-1.5\n0.002,2,4520.25,500\n";
    let read = |w, h| {
        MeasurementReader::from_reader(text.as_bytes(), "m.csv")
            .unwrap()
            .with_image_size(w, h)
            .collect::<Result<Vec<_>, _>>()
            .map_err(|e| e.to_string())
    };
    let e = read(1024, 1024).unwrap_err();
    assert!(e.starts_with("m.csv:4: field 'u': centroid u = 4520.25 px is outside the image, which is 1024 px wide"), "{e}");
    assert_eq!(read(5000, 1024).unwrap().len(), 3);
    let e = read(5000, 400).unwrap_err();
    assert!(
        e.starts_with(
            "m.csv:2: field 'v': centroid v = 500 px is outside the image, which is 400 px high"
        ),
        "{e}"
    );
}

#[test]
fn a_target_of_many_points_is_checked_for_its_unit_in_linear_time() {
    // 100,000 points of a 60 mm plate written in millimetres: the unit check (which took minutes over every pair of
    // such a file) sweeps for the farthest pair instead, and still finds the plate 60 m wide.
    let mut text = String::from("id,x,y,z\n");
    for i in 0..100_000u32 {
        let (x, y) = (f64::from(i % 317) * 0.19, f64::from(i / 317) * 0.19);
        text += &format!("{i},{x},{y},0\n");
    }
    let e = roitrack_formats::parse_target_csv_in(text.as_bytes(), "t.csv", None)
        .unwrap_err()
        .to_string();
    assert!(e.contains("--target-units mm"), "{e}");
    let target = roitrack_formats::parse_target_csv_in(
        text.as_bytes(),
        "t.csv",
        Some(roitrack_formats::LengthUnit::Mm),
    )
    .unwrap();
    assert_eq!(target.len(), 100_000);
}
