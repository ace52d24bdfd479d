//! `--foxglove`: a client of the Foxglove WebSocket protocol on loopback (tungstenite, subprotocol
//! `foxglove.sdk.v1`) subscribes to `/roitrack/pose` and `/roitrack/camera_info` of a `roitrack track --paced` run
//! and receives poses equal to the TUM file's, their bytes those of the same messages in the run's bag; bad
//! addresses and a port in use are refused, naming the flag, before anything is tracked.

use std::collections::BTreeMap;
use std::io::{BufRead, BufReader};
use std::net::{SocketAddr, TcpListener, TcpStream};
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use tungstenite::Message;
use tungstenite::client::IntoClientRequest;

mod common;
use common::{fails, ok};

fn p(path: &Path) -> &str {
    path.to_str().unwrap()
}

/// One pose of `/roitrack/pose` (geometry_msgs/msg/PoseWithCovarianceStamped), decoded here from its CDR bytes
/// (little endian, after the 4-byte encapsulation header; f64 aligned to 8 from the header's end).
#[derive(Debug)]
struct Pose {
    t_s: f64,
    frame_id: String,
    values: [f64; 7],
    covariance: [f64; 36],
}

fn decode_pose(bytes: &[u8]) -> Pose {
    assert_eq!(&bytes[..4], &[0, 1, 0, 0], "CDR little endian");
    let body = &bytes[4..];
    let u32_at = |k: usize| u32::from_le_bytes(body[k..k + 4].try_into().unwrap());
    let sec = u32_at(0) as i32;
    let nanosec = u32_at(4);
    let length = u32_at(8) as usize;
    let frame_id = std::str::from_utf8(&body[12..12 + length - 1])
        .unwrap()
        .to_string();
    assert_eq!(body[12 + length - 1], 0, "the string ends with its NUL");
    let mut at = (12 + length).next_multiple_of(8);
    let mut f64s = |n: usize| {
        let values: Vec<f64> = (0..n)
            .map(|k| f64::from_le_bytes(body[at + 8 * k..at + 8 * k + 8].try_into().unwrap()))
            .collect();
        at += 8 * n;
        values
    };
    let values = f64s(7).try_into().unwrap();
    let covariance = f64s(36).try_into().unwrap();
    assert_eq!(at, body.len(), "nothing after the covariance");
    Pose {
        t_s: f64::from(sec) + 1e-9 * f64::from(nanosec),
        frame_id,
        values,
        covariance,
    }
}

/// The TUM file's rows: time, then tx ty tz qx qy qz qw.
fn tum_rows(path: &Path) -> Vec<[f64; 8]> {
    std::fs::read_to_string(path)
        .unwrap()
        .lines()
        .filter(|l| !l.starts_with('#') && !l.trim().is_empty())
        .map(|l| {
            let v: Vec<f64> = l.split_whitespace().map(|x| x.parse().unwrap()).collect();
            v.try_into().unwrap()
        })
        .collect()
}

/// The messages of a topic of a bag, by log time (ns).
fn bag_messages(path: &Path, topic: &str) -> BTreeMap<u64, Vec<u8>> {
    let bytes = std::fs::read(path).unwrap();
    mcap::MessageStream::new(&bytes)
        .unwrap()
        .map(|m| m.unwrap())
        .filter(|m| m.channel.topic == topic)
        .map(|m| (m.log_time, m.data.into_owned()))
        .collect()
}

/// A message of a subscription: its log time, its bytes and when it arrived.
struct Received {
    log_time_ns: u64,
    data: Vec<u8>,
    at: Instant,
}

/// Connects to the live server, subscribes to `topics` (asserting their schema names), and collects every message
/// until the server closes the connection.
/// Also returns when the subscription was sent.
fn view(
    address: SocketAddr,
    topics: &[(&str, &str)],
) -> (BTreeMap<String, Vec<Received>>, Instant) {
    let stream = TcpStream::connect(address).unwrap();
    stream
        .set_read_timeout(Some(Duration::from_secs(60)))
        .unwrap();
    let mut request = format!("ws://{address}").into_client_request().unwrap();
    request.headers_mut().insert(
        "Sec-WebSocket-Protocol",
        roitrack::ros::LIVE_SUBPROTOCOL.parse().unwrap(),
    );
    let (mut socket, response) = tungstenite::client(request, stream).unwrap();
    assert_eq!(
        response.headers()["Sec-WebSocket-Protocol"],
        roitrack::ros::LIVE_SUBPROTOCOL
    );
    // Advertisements until every topic asked for is known.
    let mut channels: BTreeMap<String, (u64, serde_json::Value)> = BTreeMap::new();
    while !topics.iter().all(|(t, _)| channels.contains_key(*t)) {
        let Message::Text(text) = socket.read().unwrap() else {
            continue;
        };
        let json: serde_json::Value = serde_json::from_str(&text).unwrap();
        if json["op"] == "advertise" {
            for channel in json["channels"].as_array().unwrap() {
                channels.insert(
                    channel["topic"].as_str().unwrap().to_string(),
                    (channel["id"].as_u64().unwrap(), channel.clone()),
                );
            }
        }
    }
    let mut names = BTreeMap::new();
    let mut subscriptions = Vec::new();
    for (k, (topic, schema_name)) in topics.iter().enumerate() {
        let (id, channel) = &channels[*topic];
        assert_eq!(channel["encoding"], "cdr", "{topic}");
        assert_eq!(channel["schemaEncoding"], "ros2msg", "{topic}");
        assert_eq!(channel["schemaName"], *schema_name, "{topic}");
        let schema = channel["schema"].as_str().unwrap();
        assert_eq!(
            schema,
            roitrack::ros::msg::schema_text(schema_name).unwrap(),
            "{topic}: the bag's schema"
        );
        subscriptions.push(serde_json::json!({"id": k as u32 + 1, "channelId": id}));
        names.insert(k as u32 + 1, topic.to_string());
    }
    let subscribed = Instant::now();
    socket
        .send(Message::text(
            serde_json::json!({"op": "subscribe", "subscriptions": subscriptions}).to_string(),
        ))
        .unwrap();
    let mut received: BTreeMap<String, Vec<Received>> = BTreeMap::new();
    loop {
        match socket.read() {
            Ok(Message::Binary(data)) => {
                assert_eq!(data[0], 1, "opcode: message data");
                let subscription = u32::from_le_bytes(data[1..5].try_into().unwrap());
                let log_time_ns = u64::from_le_bytes(data[5..13].try_into().unwrap());
                received
                    .entry(names[&subscription].clone())
                    .or_default()
                    .push(Received {
                        log_time_ns,
                        data: data[13..].to_vec(),
                        at: Instant::now(),
                    });
            }
            Ok(Message::Close(_)) | Err(_) => break,
            Ok(_) => {}
        }
    }
    (received, subscribed)
}

#[test]
fn a_viewer_on_loopback_receives_the_poses_of_a_paced_run_as_in_the_tum_file_and_the_bag() {
    let dir = tempfile::tempdir().unwrap();
    let dir = dir.path();
    ok(&[
        "simulate",
        "--scenario",
        "orthoglide",
        "--duration-s",
        "2",
        "--out",
        p(dir),
    ]);
    const FACTOR: f64 = 2.0;
    let mut child = Command::new(env!("CARGO_BIN_EXE_roitrack"))
        .args([
            "track",
            "--camera",
            p(&dir.join("camera.yaml")),
            "--target",
            p(&dir.join("target.csv")),
            "--measurements",
            p(&dir.join("measurements.csv")),
            "--poses",
            p(&dir.join("poses.tum")),
            "--twists",
            p(&dir.join("twists.csv")),
            "--mcap",
            p(&dir.join("run.mcap")),
            "--frame-id",
            "cam0",
            // Port 0: a free port, which roitrack prints.
            "--foxglove",
            "127.0.0.1:0",
            "--foxglove-wait-s",
            "120",
            "--paced",
            &FACTOR.to_string(),
        ])
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut stderr = BufReader::new(child.stderr.take().unwrap());
    let mut printed = String::new();
    let address: SocketAddr = loop {
        let mut line = String::new();
        assert!(
            stderr.read_line(&mut line).unwrap() > 0,
            "roitrack ended without serving: {printed}"
        );
        printed.push_str(&line);
        if let Some(rest) = line.split("live view on ws://").nth(1) {
            break rest.split_whitespace().next().unwrap().parse().unwrap();
        }
    };
    assert_ne!(address.port(), 0);
    let reader = std::thread::spawn(move || {
        let mut rest = String::new();
        std::io::Read::read_to_string(&mut stderr, &mut rest).unwrap();
        rest
    });
    let (received, subscribed) = view(
        address,
        &[
            (
                "/roitrack/pose",
                "geometry_msgs/msg/PoseWithCovarianceStamped",
            ),
            ("/roitrack/camera_info", "sensor_msgs/msg/CameraInfo"),
        ],
    );
    let status = child.wait().unwrap();
    let rest = reader.join().unwrap();
    assert!(status.success(), "roitrack failed: {printed}{rest}");

    let tum = tum_rows(&dir.join("poses.tum"));
    let bag = bag_messages(&dir.join("run.mcap"), "/roitrack/pose");
    assert_eq!(bag.len(), tum.len());
    let poses = &received["/roitrack/pose"];
    assert!(!poses.is_empty());
    // Waiting for the subscription, the run starts after it: the viewer gets the first estimate.
    let first = decode_pose(&poses[0].data);
    assert!(
        (first.t_s - tum[0][0]).abs() < 1e-9,
        "{} {}",
        first.t_s,
        tum[0][0]
    );
    for message in poses {
        let pose = decode_pose(&message.data);
        assert_eq!(pose.frame_id, "cam0");
        assert!(pose.covariance.iter().all(|c| c.is_finite()));
        let row = tum
            .iter()
            .find(|r| (r[0] - pose.t_s).abs() < 1e-9)
            .unwrap_or_else(|| panic!("no TUM row at {}", pose.t_s));
        for (k, (a, b)) in pose.values.iter().zip(&row[1..]).enumerate() {
            assert!(
                (a - b).abs() < 1e-9,
                "t {}: value {k}: {a} against {b}",
                pose.t_s
            );
        }
        assert_eq!(
            bag.get(&message.log_time_ns),
            Some(&message.data),
            "t {}: the bag's message, byte for byte",
            pose.t_s
        );
    }
    // Paced: tracking started after the subscription, and the last pose cannot have arrived before the recording's
    // span divided by the factor had passed (a lower bound, whatever the load; unpaced, the run takes ~0.1 s).
    let last = poses.last().unwrap();
    let span_s = decode_pose(&last.data).t_s - first.t_s;
    assert!(span_s > 1.5, "{span_s}");
    let seen_s = last.at.duration_since(subscribed).as_secs_f64();
    assert!(
        seen_s >= span_s / FACTOR,
        "{seen_s} s to see {span_s} s paced at {FACTOR}"
    );
    let info = &received["/roitrack/camera_info"];
    assert!(
        !info.is_empty(),
        "the camera info is sent to a late subscriber"
    );
    eprintln!(
        "{} of {} poses received, over {seen_s:.2} s",
        poses.len(),
        tum.len()
    );
}

#[test]
fn an_address_that_does_not_parse_or_is_taken_is_refused_naming_the_flag_before_tracking() {
    let dir = tempfile::tempdir().unwrap();
    let dir = dir.path();
    ok(&[
        "simulate",
        "--scenario",
        "static",
        "--duration-s",
        "0.5",
        "--out",
        p(dir),
    ]);
    let taken = TcpListener::bind("127.0.0.1:0").unwrap();
    let port = taken.local_addr().unwrap().port().to_string();
    let file = |name: &str| dir.join(name).to_str().unwrap().to_string();
    let files = [
        file("camera.yaml"),
        file("target.csv"),
        file("measurements.csv"),
        file("poses.tum"),
        file("twists.csv"),
        file("run.mcap"),
    ];
    let track = |extra: &[&str]| {
        let mut args = vec![
            "track",
            "--camera",
            &files[0],
            "--target",
            &files[1],
            "--measurements",
            &files[2],
            "--poses",
            &files[3],
            "--twists",
            &files[4],
            "--mcap",
            &files[5],
        ];
        args.extend_from_slice(extra);
        fails(&args)
    };
    let in_use = format!("127.0.0.1:{port}");
    let error = track(&["--foxglove", &in_use]);
    assert!(
        error.contains(&format!("--foxglove {in_use}")) && error.contains("cannot listen"),
        "{error}"
    );
    for bad in ["nonsense", "127.0.0.1", "127.0.0.1:99999", "300.1.1.1:80"] {
        let error = track(&["--foxglove", bad]);
        assert!(
            error.contains("--foxglove") && error.contains("ADDR:PORT"),
            "{bad}: {error}"
        );
    }
    let error = track(&["--foxglove-wait-s", "3"]);
    assert!(error.contains("--foxglove"), "{error}");
    for bad in ["0", "-1", "inf", "x"] {
        let error = track(&[&format!("--paced={bad}")]);
        assert!(error.contains("--paced"), "{bad}: {error}");
    }
    // Nothing was tracked or written: the address is checked first.
    for file in ["poses.tum", "twists.csv", "run.mcap"] {
        assert!(!dir.join(file).exists(), "{file}");
    }
    drop(taken);
}

#[test]
fn the_demo_publishes_its_default_estimators_poses_from_its_loop() {
    let dir = tempfile::tempdir().unwrap();
    let dir = dir.path();
    let poses = viewed_poses(Command::new(env!("CARGO_BIN_EXE_roitrack")).args([
        "demo",
        "--out",
        p(dir),
        "--foxglove",
        "127.0.0.1:0",
        "--foxglove-wait-s",
        "120",
    ]));
    let tum = tum_rows(&dir.join("kalman_poses.tum"));
    assert!(!poses.is_empty());
    assert_poses_are_rows(&poses, &tum);
    eprintln!("{} of {} poses received", poses.len(), tum.len());
}

/// Runs `command` (a roitrack run with `--foxglove 127.0.0.1:0`), views its poses as they come, and returns them
/// once the run has ended successfully.
fn viewed_poses(command: &mut Command) -> Vec<Received> {
    let mut child = command
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut stderr = BufReader::new(child.stderr.take().unwrap());
    let address: SocketAddr = loop {
        let mut line = String::new();
        assert!(stderr.read_line(&mut line).unwrap() > 0, "no live view");
        if let Some(rest) = line.split("live view on ws://").nth(1) {
            break rest.split_whitespace().next().unwrap().parse().unwrap();
        }
    };
    let reader = std::thread::spawn(move || {
        let mut rest = String::new();
        std::io::Read::read_to_string(&mut stderr, &mut rest).unwrap();
        rest
    });
    let (mut received, _) = view(
        address,
        &[(
            "/roitrack/pose",
            "geometry_msgs/msg/PoseWithCovarianceStamped",
        )],
    );
    let status = child.wait().unwrap();
    let rest = reader.join().unwrap();
    assert!(status.success(), "the run failed: {rest}");
    received.remove("/roitrack/pose").unwrap_or_default()
}

/// Every pose received is the TUM file's row at its time, to 1e-9, in the camera frame.
fn assert_poses_are_rows(poses: &[Received], tum: &[[f64; 8]]) {
    for message in poses {
        let pose = decode_pose(&message.data);
        assert_eq!(pose.frame_id, "camera");
        let row = tum
            .iter()
            .find(|r| (r[0] - pose.t_s).abs() < 1e-9)
            .unwrap_or_else(|| panic!("no TUM row at {}", pose.t_s));
        for (a, b) in pose.values.iter().zip(&row[1..]) {
            assert!((a - b).abs() < 1e-9, "t {}: {a} against {b}", pose.t_s);
        }
    }
}

/// `live --fake --foxglove`: the poses come while the camera runs (spread over the run, not all at its end), and they
/// are the run's own.
#[cfg(feature = "genicam")]
#[test]
fn the_live_camera_publishes_its_poses_while_it_runs() {
    let dir = tempfile::tempdir().unwrap();
    let dir = dir.path();
    let (poses, twists) = (dir.join("p.tum"), dir.join("t.csv"));
    let messages = viewed_poses(
        Command::new(env!("CARGO_BIN_EXE_roitrack"))
            .args(["live", "--fake", "--duration", "2", "--poses"])
            .arg(&poses)
            .arg("--twists")
            .arg(&twists)
            .args(["--foxglove", "127.0.0.1:0", "--foxglove-wait-s", "120"]),
    );
    let tum = tum_rows(&poses);
    assert!(
        messages.len() > tum.len() / 2,
        "{} of {}",
        messages.len(),
        tum.len()
    );
    assert_poses_are_rows(&messages, &tum);
    // 2 s of the scenario at the fake camera's rate (about 2,000 ROIs/s for 8,000 ROIs): seconds of wall time; poses
    // published only at the end would all arrive within milliseconds.
    let spread = messages.last().unwrap().at - messages.first().unwrap().at;
    assert!(spread > Duration::from_millis(500), "{spread:?}");
    eprintln!(
        "{} of {} poses received over {spread:?}",
        messages.len(),
        tum.len()
    );
}
