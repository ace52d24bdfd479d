//! A tracker's estimates as files: poses (TUM), twists (CSV) and, optionally, diagnostics (CSV) and the full
//! covariance (CSV, see [`CovarianceWriter`]), written together.
//!
//! The diagnostics CSV has one row per estimate, with a header:
//!
//! ```text
//! t,status,residual_rms_px,inverse_condition,measurements_used,iterations,sigma_x_m,sigma_y_m,sigma_z_m,sigma_vx_mps,sigma_vy_mps,sigma_vz_mps
//! ```
//!
//! `status` is one of `converging`, `tracking`, `degenerate`, `disputed`, `lost` (only the first two are vouched for);
//! the sigmas are the 1-sigma standard deviations of the estimate's covariance, the square roots of its diagonal
//! entries `c0_0`, `c1_1`, `c2_2` (position of the object's origin in the camera frame, m) and `c6_6`, `c7_7`, `c8_8`
//! (velocity of the object's origin, camera frame, m/s) in the covariance file; `NaN` for an estimate without a
//! covariance (the static baseline's, a degenerate window's), whose covariance row is `NaN` throughout.

use std::io::Write;
use std::path::Path;

use roitrack_core::{PoseSample, TwistSample};
use roitrack_estimators::Estimate;

use crate::{AtomicFile, CovarianceWriter, FormatError, PoseWriter, TwistWriter};

/// The diagnostics CSV's header line.
pub const DIAGNOSTICS_HEADER: &str = "t,status,residual_rms_px,inverse_condition,measurements_used,iterations,\
    sigma_x_m,sigma_y_m,sigma_z_m,sigma_vx_mps,sigma_vy_mps,sigma_vz_mps";

/// Writes estimates as TUM poses, twists CSV, optional diagnostics CSV and optional covariance CSV
/// ([`Self::with_covariance`]), each atomically: the files appear only on [`Self::finish`], so a failed or interrupted
/// run leaves the previous files as they were.
///
/// ```
/// use roitrack_estimators::{Estimate, TrackStatus};
/// use roitrack_core::MotionState;
/// use roitrack_formats::EstimateWriter;
///
/// # fn main() -> Result<(), roitrack_formats::FormatError> {
/// let dir = tempfile::tempdir().unwrap();
/// let (poses, twists, diagnostics, covariance) = (
///     dir.path().join("p.tum"),
///     dir.path().join("t.csv"),
///     dir.path().join("d.csv"),
///     dir.path().join("c.csv"),
/// );
/// let mut writer =
///     EstimateWriter::create(&poses, &twists, Some(&diagnostics))?.with_covariance(Some(&covariance))?;
/// writer.write(&Estimate {
///     t_ref_s: 0.5,
///     state: MotionState::at_rest(Default::default(), nalgebra::Vector3::new(0.0, 0.0, 0.6)),
///     residual_rms_px: 0.1,
///     inverse_condition: 0.2,
///     measurements_used: 16,
///     iterations: 1,
///     status: TrackStatus::Tracking,
///     covariance: None,
///     noise_px: 0.1,
///     acceleration: None,
/// })?;
/// writer.finish()?;
/// let text = std::fs::read_to_string(&diagnostics).unwrap();
/// assert_eq!(text.lines().nth(1), Some("0.5,tracking,0.1,0.2,16,1,NaN,NaN,NaN,NaN,NaN,NaN"));
/// // No covariance: 78 NaN entries after the time.
/// let text = std::fs::read_to_string(&covariance).unwrap();
/// assert_eq!(text.lines().nth(1), Some(format!("0.5{}", ",NaN".repeat(78)).as_str()));
/// # Ok(())
/// # }
/// ```
pub struct EstimateWriter {
    poses: PoseWriter,
    twists: TwistWriter,
    diagnostics: Option<AtomicFile>,
    covariance: Option<CovarianceWriter>,
}

impl EstimateWriter {
    /// Starts the files (their folders must exist).
    pub fn create(
        poses: &Path,
        twists: &Path,
        diagnostics: Option<&Path>,
    ) -> Result<Self, FormatError> {
        let diagnostics = match diagnostics {
            Some(path) => {
                let mut file = AtomicFile::create(path)?;
                writeln!(file, "{DIAGNOSTICS_HEADER}")
                    .map_err(|e| FormatError::io(path, "cannot write", e))?;
                Some(file)
            }
            None => None,
        };
        Ok(Self {
            poses: PoseWriter::create(poses)?,
            twists: TwistWriter::create(twists)?,
            diagnostics,
            covariance: None,
        })
    }

    /// Also writes each estimate's full 12 x 12 covariance to `path` (see [`CovarianceWriter`]), if given; `None`
    /// leaves the writer as it was.
    pub fn with_covariance(mut self, path: Option<&Path>) -> Result<Self, FormatError> {
        if let Some(path) = path {
            self.covariance = Some(CovarianceWriter::create(path)?);
        }
        Ok(self)
    }

    /// Appends one estimate to every file.
    pub fn write(&mut self, e: &Estimate) -> Result<(), FormatError> {
        self.poses
            .write(&PoseSample::from_state(e.t_ref_s, &e.state))?;
        self.twists
            .write(&TwistSample::from_state(e.t_ref_s, &e.state))?;
        if let Some(file) = self.diagnostics.as_mut() {
            let sigma = e.standard_deviations();
            writeln!(
                file,
                "{},{},{},{},{},{},{},{},{},{},{},{}",
                e.t_ref_s,
                e.status.name(),
                e.residual_rms_px,
                e.inverse_condition,
                e.measurements_used,
                e.iterations,
                sigma[0],
                sigma[1],
                sigma[2],
                sigma[6],
                sigma[7],
                sigma[8]
            )
            .map_err(|error| FormatError::io(file.path(), "cannot write", error))?;
        }
        if let Some(file) = self.covariance.as_mut() {
            file.write_estimate(e)?;
        }
        Ok(())
    }

    /// Completes every file and moves it into place.
    pub fn finish(self) -> Result<(), FormatError> {
        self.poses.finish()?;
        self.twists.finish()?;
        if let Some(file) = self.diagnostics {
            file.finish()?;
        }
        if let Some(file) = self.covariance {
            file.finish()?;
        }
        Ok(())
    }
}
