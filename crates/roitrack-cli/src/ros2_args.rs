//! `--ros2` (with `--ros2-domain`, `--ros2-namespace`, `--ros2-interface`, `--ros2-wait-s`): the estimates published live on the ROS 2 DDS
//! bus while tracking, as the node `roitrack` (the cargo feature `ros2`; see `roitrack_ros::ros2`, docs/ros2.md). A
//! command takes them by flattening [`Ros2Args`] into its arguments, then [`Ros2Args::start`] before tracking,
//! [`Ros2::estimate`] per estimate and [`Ros2::finish`] at the end.

use anyhow::Result;
use clap::Args;
use roitrack::formats::FormatError;
use roitrack::ros::BagOptions;
use roitrack::{CameraModel, Estimate};

/// How to build a binary that publishes on ROS 2.
#[cfg(not(feature = "ros2"))]
const ROS2_BUILD: &str = "cargo build --release -p roitrack-cli --features ros2";

/// The options of publishing on ROS 2.
#[derive(Debug, Clone, Args)]
pub struct Ros2Args {
    /// Publish the estimates live on the ROS 2 DDS bus as the node `roitrack`, while tracking: /roitrack/pose,
    /// /roitrack/twist, /roitrack/odometry, /tf and /roitrack/status per estimate (best effort; /tf reliable, as tf2
    /// listeners want it), /roitrack/camera_info once (reliable, transient local), the types and frames of --mcap's
    /// bag (docs/ros2.md). DDS finds its peers by multicast on every network interface: choose the domain with
    /// --ros2-domain, the interfaces as docs/ros2.md says. A tracker never waits for the bus: an estimate the
    /// publisher is too far behind for is dropped and counted. Only in a binary built with the cargo feature ros2.
    /// Default: not published.
    #[arg(long)]
    pub ros2: bool,
    /// With --ros2: the DDS domain (ROS_DOMAIN_ID), 0 to 232; only nodes of the same domain see each other. Default:
    /// the environment's ROS_DOMAIN_ID, else 0.
    #[arg(long, value_name = "ID", requires = "ros2", value_parser = parse_domain)]
    pub ros2_domain: Option<u16>,
    /// With --ros2: the node's namespace, put before every topic (/robot1: /robot1/roitrack/pose, /robot1/tf).
    /// Default: none.
    #[arg(long, value_name = "NS", requires = "ros2")]
    pub ros2_namespace: Option<String>,
    /// With --ros2: use only the network interface with this IPv4 address (repeat for several) for DDS's multicast
    /// discovery and the locators it announces, e.g. the robot's network rather than the office's (--ros2-interface
    /// 127.0.0.1: this machine only, with multicast on lo). The interface must be up. Default: every interface that
    /// is up.
    #[arg(long, value_name = "ADDR", requires = "ros2")]
    pub ros2_interface: Vec<std::net::IpAddr>,
    /// With --ros2: before tracking, wait up to S seconds for a subscriber on every estimate topic (then start
    /// anyway), so that it receives the run from its start. Default: no wait.
    #[arg(long, value_name = "S", requires = "ros2", value_parser = parse_wait_s)]
    pub ros2_wait_s: Option<f64>,
}

/// Where a node that is always on the bus (`ros2-node`) speaks: --ros2-domain, --ros2-namespace and
/// --ros2-interface as [`Ros2Args`] has them, without --ros2.
#[derive(Debug, Clone, Args)]
pub struct Ros2BusArgs {
    /// The DDS domain (ROS_DOMAIN_ID), 0 to 232; only nodes of the same domain see each other. Default: the
    /// environment's ROS_DOMAIN_ID, else 0.
    #[arg(long, value_name = "ID", value_parser = parse_domain)]
    pub ros2_domain: Option<u16>,
    /// The node's namespace, put before every topic, those it subscribes to and those it publishes. Default: none.
    #[arg(long, value_name = "NS")]
    pub ros2_namespace: Option<String>,
    /// Use only the network interface with this IPv4 address (repeat for several). Default: every interface up.
    #[arg(long, value_name = "ADDR")]
    pub ros2_interface: Vec<std::net::IpAddr>,
}

#[cfg(feature = "ros2")]
impl Ros2BusArgs {
    /// The options of the node's subscriber and publisher.
    pub fn options(&self) -> Result<roitrack_ros::ros2::Ros2Options> {
        Ok(roitrack_ros::ros2::Ros2Options {
            domain_id: domain(self.ros2_domain)?,
            namespace: self.ros2_namespace.clone().unwrap_or_default(),
            wait_for_subscribers_s: None,
            interfaces: self.ros2_interface.clone(),
        })
    }
}

fn parse_domain(text: &str) -> Result<u16, String> {
    match text.trim().parse::<u16>() {
        Ok(id) if id <= 232 => Ok(id),
        _ => Err(
            "expected a DDS domain id, a whole number from 0 to 232 (RTPS's ports for higher ones overflow)"
                .into(),
        ),
    }
}

fn parse_wait_s(text: &str) -> Result<f64, String> {
    match text.parse::<f64>() {
        Ok(s) if (0.0..=3600.0).contains(&s) => Ok(s),
        _ => Err("expected seconds, a number from 0 to 3600 (an hour)".into()),
    }
}

/// The domain: --ros2-domain, else the environment's ROS_DOMAIN_ID (as every ROS 2 node reads it), else 0.
#[cfg_attr(not(feature = "ros2"), allow(dead_code))]
fn domain(given: Option<u16>) -> Result<u16> {
    if let Some(id) = given {
        return Ok(id);
    }
    match std::env::var("ROS_DOMAIN_ID") {
        Ok(text) if !text.trim().is_empty() => parse_domain(&text)
            .map_err(|e| anyhow::anyhow!("the environment's ROS_DOMAIN_ID {text:?}: {e}")),
        _ => Ok(0),
    }
}

/// The publisher, when --ros2 was given.
#[derive(Debug, Default)]
pub struct Ros2 {
    #[cfg(feature = "ros2")]
    publisher: Option<roitrack_ros::ros2::Ros2Publisher>,
}

impl Ros2Args {
    /// Starts the node (and waits for subscribers with --ros2-wait-s) when --ros2 was given; `camera` goes to
    /// /roitrack/camera_info (a rig's run has none), `options` gives the frame ids. A node that cannot start (no network interface, the
    /// domain's ports taken, a bad namespace) is an error here, before tracking.
    pub fn start(&self, camera: Option<&CameraModel>, options: &BagOptions) -> Result<Ros2> {
        if !self.ros2 {
            return Ok(Ros2::default());
        }
        #[cfg(not(feature = "ros2"))]
        {
            let _ = (camera, options);
            anyhow::bail!(
                "--ros2: this binary was built without ROS 2; build it with the cargo feature ros2 ({ROS2_BUILD})"
            );
        }
        #[cfg(feature = "ros2")]
        {
            use roitrack_ros::ros2::{Ros2Options, Ros2Publisher};
            let ros2_options = Ros2Options {
                domain_id: domain(self.ros2_domain)?,
                namespace: self.ros2_namespace.clone().unwrap_or_default(),
                wait_for_subscribers_s: self.ros2_wait_s,
                interfaces: self.ros2_interface.clone(),
            };
            if let Some(wait_s) = self.ros2_wait_s {
                eprintln!(
                    "roitrack: waiting up to {wait_s} s for subscribers on the ROS 2 estimate topics"
                );
            }
            let publisher = Ros2Publisher::start(&ros2_options, options, camera.cloned())
                .map_err(|e| anyhow::anyhow!("--ros2: {e}"))?;
            eprintln!(
                "roitrack: publishing on ROS 2 as the {}",
                publisher.description()
            );
            if self.ros2_wait_s.is_some() && !publisher.subscribed_at_start() {
                eprintln!("roitrack: not every estimate topic has a subscriber; tracking anyway");
            }
            Ok(Ros2 {
                publisher: Some(publisher),
            })
        }
    }
}

impl Ros2 {
    /// Hands an estimate to the publisher (never waits).
    pub fn estimate(&mut self, estimate: &Estimate) -> Result<(), FormatError> {
        #[cfg(feature = "ros2")]
        if let Some(publisher) = &mut self.publisher {
            return publisher.publish_estimate(estimate);
        }
        let _ = estimate;
        Ok(())
    }

    /// Publishes what is pending, stops the node and says what it published.
    pub fn finish(self) -> Result<()> {
        #[cfg(feature = "ros2")]
        if let Some(publisher) = self.publisher {
            let description = publisher.description().to_string();
            let report = publisher.finish()?;
            eprintln!(
                "roitrack: {description}: {} estimates published, {} dropped (the publisher was behind), {} \
                 reliable messages refused (a subscriber was behind)",
                report.published, report.dropped, report.refused
            );
        }
        Ok(())
    }
}
