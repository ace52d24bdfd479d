//! `roitrack target`: write a bundled target (and the canonical camera) to files.

use std::path::PathBuf;

use anyhow::Result;
use clap::{Args, ValueEnum};
use roitrack::{CameraModel, Target};

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum BundledTarget {
    /// 4 x 4 planar grid, pitch 20 mm, 6 mm blobs, 9 mm key blob 0 (SPEC section 6).
    Grid4x4,
}

/// Write a bundled target as a target CSV (id,x,y,z,diameter in metres), and optionally the canonical camera.
#[derive(Debug, Args)]
pub struct TargetArgs {
    /// Which bundled target.
    #[arg(long, value_enum, default_value = "grid4x4")]
    pub name: BundledTarget,
    /// Output target CSV.
    #[arg(long)]
    pub out: PathBuf,
    /// Also write the canonical camera of SPEC section 6 (ROS camera_info YAML) here.
    #[arg(long)]
    pub camera_out: Option<PathBuf>,
}

pub fn run(args: &TargetArgs) -> Result<()> {
    let target = match args.name {
        BundledTarget::Grid4x4 => Target::grid4x4(),
    };
    roitrack::formats::write_target_csv(&args.out, &target)?;
    if let Some(path) = &args.camera_out {
        roitrack::formats::write_camera_yaml(path, &CameraModel::canonical())?;
    }
    Ok(())
}
