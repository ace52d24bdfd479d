//! One module per subcommand; the lab's (feature `lab`) under `lab/`.

pub mod calibrate_rig;
pub mod demo;
pub mod detect;
pub mod eval;
#[cfg(feature = "lab")]
pub mod lab;
#[cfg(feature = "genicam")]
pub mod live;
pub mod plot;
#[cfg(feature = "ros2")]
pub mod ros2_node;
pub mod servo;
pub mod servo_live;
pub mod simulate;
pub mod target;
pub mod track;
