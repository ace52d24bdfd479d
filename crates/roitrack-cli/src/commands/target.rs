//! `roitrack target`: write a bundled target (and the canonical camera), or a circle grid of any size, to files.

use std::path::PathBuf;

use anyhow::{Result, anyhow};
use clap::{Args, Subcommand, ValueEnum};
use roitrack::core::target::{CircleGrid, GridLayout};
use roitrack::{CameraModel, Target};

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum BundledTarget {
    /// 4 x 4 planar grid, pitch 20 mm, 6 mm blobs, 9 mm key blob 0 (docs/model.md).
    Grid4x4,
}

/// Write a target CSV (id,x,y,z,diameter in metres): the bundled grid4x4 (and optionally the canonical camera), or
/// a circle grid of any size (`roitrack target grid`).
#[derive(Debug, Args)]
#[command(args_conflicts_with_subcommands = true, subcommand_negates_reqs = true)]
pub struct TargetArgs {
    #[command(subcommand)]
    pub command: Option<TargetCommand>,
    /// Which bundled target.
    #[arg(long, value_enum, default_value = "grid4x4")]
    pub name: BundledTarget,
    /// Output target CSV.
    #[arg(long, required = true)]
    pub out: Option<PathBuf>,
    /// Also write the built-in camera (1024 x 1024 px, fx = fy = 1500 px; docs/model.md) here, as ROS camera_info
    /// YAML. Default: not written.
    #[arg(long)]
    pub camera_out: Option<PathBuf>,
}

#[derive(Debug, Subcommand)]
pub enum TargetCommand {
    Grid(GridArgs),
}

/// Write a planar grid of equal circles (z = 0) as a target CSV.
///
/// Layouts, with S the spacing: square (the default) puts a circle at every row and column, at (x, y) =
/// (col S, row S); --hexagonal puts one where row + col has the parity of rows - 1 (the last row holds columns 0, 2,
/// 4, ..., the one before it columns 1, 3, 5, ...), at (x, y) = (col S / 2, row S sin 60°), so that every circle's six
/// neighbours are S away. Seen from its front (x to the right, y down) the bottom row starts at the left edge, as
/// printed hexagonal boards (BoofCV's) do; with the other parity a pose would see the board from behind.
///
/// Ids: id 0 is the first circle of row 0; the ids then run row by row, and within a row by increasing column
/// (square: id = row * cols + col, id 0 at the origin). Every circle has the same diameter, so the target has no key
/// blob.
///
/// Example: `roitrack target grid --rows 24 --cols 28 --spacing-m 0.012 --diameter-m 0.006 --hexagonal --out
/// board.csv` writes 336 circles, ids 0-13 on row 0 (columns 1, 3, ..., 27), the last, id 335, at
/// (0.156, 0.2390, 0) m.
#[derive(Debug, Args)]
pub struct GridArgs {
    /// Number of rows (along y).
    #[arg(long)]
    pub rows: u32,
    /// Number of columns (along x).
    #[arg(long)]
    pub cols: u32,
    /// Distance between the centres of neighbouring circles (m).
    #[arg(long, allow_negative_numbers = true)]
    pub spacing_m: f64,
    /// Diameter of every circle (m), smaller than the spacing.
    #[arg(long, allow_negative_numbers = true)]
    pub diameter_m: f64,
    /// Hexagonal layout (every other position, the last row starting at column 0; rows S sin 60° apart) instead of
    /// square.
    #[arg(long)]
    pub hexagonal: bool,
    /// Output target CSV.
    #[arg(long)]
    pub out: PathBuf,
}

pub fn run(args: &TargetArgs) -> Result<()> {
    if let Some(TargetCommand::Grid(grid)) = &args.command {
        return run_grid(grid);
    }
    // clap requires --out when there is no subcommand.
    let out = args
        .out
        .as_ref()
        .ok_or_else(|| anyhow!("--out is required"))?;
    if let Some(camera_out) = &args.camera_out {
        roitrack::formats::check_output_paths(
            &[],
            &[("--out", out), ("--camera-out", camera_out)],
        )?;
    }
    let target = match args.name {
        BundledTarget::Grid4x4 => Target::grid4x4(),
    };
    roitrack::formats::write_target_csv(out, &target)?;
    if let Some(path) = &args.camera_out {
        roitrack::formats::write_camera_yaml(path, &CameraModel::canonical())?;
    }
    Ok(())
}

fn run_grid(args: &GridArgs) -> Result<()> {
    let spec = CircleGrid {
        rows: args.rows,
        cols: args.cols,
        spacing_m: args.spacing_m,
        diameter_m: args.diameter_m,
        layout: if args.hexagonal {
            GridLayout::Hexagonal
        } else {
            GridLayout::Square
        },
    };
    let target = Target::circle_grid(&spec)?;
    roitrack::formats::write_target_csv(&args.out, &target)?;
    Ok(())
}
