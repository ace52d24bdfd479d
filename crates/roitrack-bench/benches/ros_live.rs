//! Benchmark of the live view (`track --foxglove`) against tracking itself: publishing must not slow the tracking
//! thread noticeably, whether a viewer is connected or not.
//!
//! - `ros_live/track_orthoglide`: the default estimator over the orthoglide scenario's measurements (seed 1, 4 kHz,
//!   1,963 estimates), estimates kept in memory.
//! - `ros_live/track_orthoglide_live_no_client`: the same, each estimate also handed to a [`LiveServer`] on
//!   127.0.0.1 with no client (nothing is handed over: an atomic load per estimate).
//! - `ros_live/track_orthoglide_live_client`: the same with a WebSocket client on loopback (tungstenite, on a thread
//!   of this process) subscribed to every topic and reading every message: the server's publishing thread
//!   serialises pose, twist, odometry, tf and status per estimate and its runtime sends them.
//!
//! At the end, from passes of each timed alternately (best of 7), the ratios of the tracking with the live view to
//! the tracking alone (wall time: on a machine with no free core the server's threads compete with the tracker), and
//! the tracking thread's own CPU time (Linux's `/proc/thread-self/schedstat`) over 20 passes of each: what handing
//! the estimates over costs it, whatever the load; and how many estimates were dropped (publishing thread behind).
//! `cargo bench -p roitrack-bench --bench ros_live` (about 20 s); `-- --quick` for a shorter run.

use std::net::TcpStream;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::{Duration, Instant};

use criterion::{Criterion, criterion_group, criterion_main};
use roitrack_bench::cpu_time_of;
use roitrack_core::{CameraModel, Measurement, Target};
use roitrack_estimators::{Estimate, Tracker, TrackerConfig, track};
use roitrack_ros::{BagOptions, LIVE_SUBPROTOCOL, LiveServer};
use roitrack_sim::{Scenario, ScenarioKind, SimulationOptions, simulate};
use tungstenite::Message;
use tungstenite::client::IntoClientRequest;

struct Scene {
    camera: CameraModel,
    target: Target,
    measurements: Vec<Measurement>,
}

fn track_into(scene: &Scene, mut sink: impl FnMut(&Estimate)) -> usize {
    let mut tracker = Tracker::new(
        scene.camera.clone(),
        scene.target.clone(),
        TrackerConfig::default(),
    )
    .expect("a valid tracker");
    let mut count = 0;
    track(
        &mut tracker,
        scene.measurements.iter().map(|m| Ok::<_, ()>(*m)),
        |e: &Estimate| {
            count += 1;
            sink(e);
            Ok::<_, ()>(())
        },
    )
    .expect("the scenario tracks");
    count
}

fn track_alone(scene: &Scene) -> Vec<Estimate> {
    let mut estimates = Vec::with_capacity(scene.measurements.len() / 8);
    track_into(scene, |e| estimates.push(*e));
    estimates
}

fn track_live(scene: &Scene, live: &mut LiveServer) -> Vec<Estimate> {
    let mut estimates = Vec::with_capacity(scene.measurements.len() / 8);
    track_into(scene, |e| {
        estimates.push(*e);
        live.publish_estimate(e).expect("the live server runs");
    });
    estimates
}

/// A viewer: subscribes to every advertised topic and reads until told to stop; counts the messages.
fn spawn_client(
    address: std::net::SocketAddr,
    stop: Arc<AtomicBool>,
    messages: Arc<AtomicU64>,
) -> std::thread::JoinHandle<()> {
    std::thread::spawn(move || {
        let stream = TcpStream::connect(address).expect("the server accepts");
        stream
            .set_read_timeout(Some(Duration::from_millis(200)))
            .unwrap();
        let mut request = format!("ws://{address}").into_client_request().unwrap();
        request
            .headers_mut()
            .insert("Sec-WebSocket-Protocol", LIVE_SUBPROTOCOL.parse().unwrap());
        let (mut socket, _) = tungstenite::client(request, stream).expect("the handshake");
        let mut subscribed = 0;
        while !stop.load(Ordering::Relaxed) {
            match socket.read() {
                Ok(Message::Text(text)) => {
                    let json: serde_json::Value = serde_json::from_str(&text).unwrap();
                    if json["op"] == "advertise" {
                        let subscriptions: Vec<_> = json["channels"]
                            .as_array()
                            .unwrap()
                            .iter()
                            .map(|c| {
                                subscribed += 1;
                                serde_json::json!({"id": subscribed, "channelId": c["id"]})
                            })
                            .collect();
                        socket
                            .send(Message::text(
                                serde_json::json!({"op": "subscribe", "subscriptions": subscriptions})
                                    .to_string(),
                            ))
                            .unwrap();
                    }
                }
                Ok(Message::Binary(_)) => {
                    messages.fetch_add(1, Ordering::Relaxed);
                }
                Ok(Message::Close(_)) => break,
                Ok(_) => {}
                Err(tungstenite::Error::Io(e))
                    if matches!(
                        e.kind(),
                        std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                    ) => {}
                Err(_) => break,
            }
        }
    })
}

fn timed(pass: impl FnOnce()) -> Duration {
    let start = Instant::now();
    pass();
    start.elapsed()
}

fn start_server(scene: &Scene) -> LiveServer {
    LiveServer::start(
        "127.0.0.1:0".parse().unwrap(),
        &BagOptions::default(),
        Some(scene.camera.clone()),
        None,
    )
    .expect("the live server starts")
}

fn ros_live(c: &mut Criterion) {
    let run = simulate(
        &Scenario::new(ScenarioKind::Orthoglide, 1),
        &SimulationOptions::default(),
    )
    .expect("the scenario simulates");
    let scene = Scene {
        camera: run.camera.clone(),
        target: run.target.clone(),
        measurements: run.measurements.clone(),
    };
    let mut quiet = start_server(&scene);
    let mut watched = start_server(&scene);
    let (stop, messages) = (
        Arc::new(AtomicBool::new(false)),
        Arc::new(AtomicU64::new(0)),
    );
    let client = spawn_client(watched.address(), stop.clone(), messages.clone());
    assert!(
        watched.wait_for_subscriber(Duration::from_secs(30)),
        "the client subscribes"
    );
    // Subscriptions of the client's six topics (the camera info's channel is advertised from the start).
    let deadline = Instant::now() + Duration::from_secs(10);
    while watched.subscriptions() < 6 && Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(10));
    }
    eprintln!(
        "ros_live: {} measurements, {} estimates; the client holds {} subscriptions",
        scene.measurements.len(),
        track_alone(&scene).len(),
        watched.subscriptions()
    );

    let mut group = c.benchmark_group("ros_live");
    group.bench_function("track_orthoglide", |b| b.iter(|| track_alone(&scene)));
    group.bench_function("track_orthoglide_live_no_client", |b| {
        b.iter(|| track_live(&scene, &mut quiet))
    });
    group.bench_function("track_orthoglide_live_client", |b| {
        b.iter(|| track_live(&scene, &mut watched))
    });
    group.finish();

    let (mut alone, mut no_client, mut with_client) = (Duration::MAX, Duration::MAX, Duration::MAX);
    for _ in 0..7 {
        alone = alone.min(timed(|| {
            std::hint::black_box(track_alone(&scene));
        }));
        no_client = no_client.min(timed(|| {
            std::hint::black_box(track_live(&scene, &mut quiet));
        }));
        with_client = with_client.min(timed(|| {
            std::hint::black_box(track_live(&scene, &mut watched));
        }));
        // The publishing thread catches up between passes, as it would between estimates of a real run.
        std::thread::sleep(Duration::from_millis(50));
    }
    let ms = |d: Duration| d.as_secs_f64() * 1e3;
    eprintln!(
        "ros_live: wall time, best of 7: tracking {:.2} ms; with the live view and no client {:.2} ms (ratio \
         {:.3}); with a subscribed client {:.2} ms (ratio {:.3})",
        ms(alone),
        ms(no_client),
        no_client.as_secs_f64() / alone.as_secs_f64(),
        ms(with_client),
        with_client.as_secs_f64() / alone.as_secs_f64(),
    );
    let cpu_alone = cpu_time_of(20, || {
        std::hint::black_box(track_alone(&scene));
    });
    let cpu_client = cpu_time_of(20, || {
        std::hint::black_box(track_live(&scene, &mut watched));
    });
    if let (Some(a), Some(b)) = (cpu_alone, cpu_client) {
        eprintln!(
            "ros_live: the tracking thread's CPU time over 20 passes: {:.1} ms alone, {:.1} ms handing every \
             estimate to the live view with a subscribed client (ratio {:.3})",
            ms(a),
            ms(b),
            b.as_secs_f64() / a.as_secs_f64()
        );
    }
    std::thread::sleep(Duration::from_millis(300));
    let quiet_report = quiet.finish().expect("the server stops");
    let report = watched.finish().expect("the server stops");
    stop.store(true, Ordering::Relaxed);
    let _ = client.join();
    eprintln!(
        "ros_live: with a client: {} estimates handed over, {} published, {} dropped (publishing thread behind); \
         the client read {} messages; without a client: {} given, {} left out (no viewer)",
        report.handed,
        report.published,
        report.dropped,
        messages.load(Ordering::Relaxed),
        quiet_report.handed,
        quiet_report.unseen,
    );
}

criterion_group!(benches, ros_live);
criterion_main!(benches);
