//! The calibration flags of every command that runs the render workers.

use std::path::PathBuf;

use glint_eval::active::Calibration;
use glint_geometry::Part;

/// `--material FILE --response FILE`: the part's calibration, else the one shipped for it.
#[derive(clap::Args, Clone, Debug, Default)]
pub struct CalibrationArgs {
    /// The part's fitted material (`glint calibrate bsdf`); without it, the calibration shipped
    /// for the part (assets/calibration/: the Zigzag's).
    #[arg(long, requires = "response")]
    pub material: Option<PathBuf>,
    /// The camera response (`glint calibrate response`) that goes with --material.
    #[arg(long, requires = "material")]
    pub response: Option<PathBuf>,
}

impl CalibrationArgs {
    pub fn load(&self, part: Part) -> anyhow::Result<Calibration> {
        Ok(Calibration::from_files_or_embedded(
            part,
            self.material.as_deref(),
            self.response.as_deref(),
        )?)
    }
}
