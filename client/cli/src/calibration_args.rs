//! The calibration flags of every command that runs the render workers.

use std::path::PathBuf;

use glint_eval::active::Calibration;
use glint_geometry::Part;

/// `--material FILE --response FILE`: the part's calibration, else the one shipped for it.
#[derive(clap::Args, Clone, Debug, Default)]
pub struct CalibrationArgs {
    /// The part's fitted material (`glint calibrate bsdf`); without it, the calibration shipped
    /// for the part (assets/calibration/).
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

/// The calibrations of several parts: `--calibrations DIR` (DIR/<part>/material.json and
/// response.json, the layout `glint demo` caches), or `--material/--response` for one part;
/// a part without either uses the calibration shipped for it.
#[derive(clap::Args, Clone, Debug, Default)]
pub struct PartCalibrationArgs {
    /// Each part's calibration is read from DIR/<part>/material.json and response.json (the
    /// layout `glint demo` caches in glint-out/calibration); a part without one there uses the
    /// calibration shipped with Glint (assets/calibration/).
    #[arg(long)]
    pub calibrations: Option<PathBuf>,
    #[command(flatten)]
    pub one: CalibrationArgs,
}

impl PartCalibrationArgs {
    /// `part`'s calibration: `--material/--response`, else `DIR/<part>/` of `--calibrations`,
    /// else the one shipped.
    pub fn load(&self, part: Part) -> anyhow::Result<Calibration> {
        if self.one.material.is_some() {
            return self.one.load(part);
        }
        if let Some(root) = &self.calibrations {
            let dir = root.join(part.name());
            let (m, r) = (dir.join("material.json"), dir.join("response.json"));
            if m.is_file() && r.is_file() {
                return Ok(Calibration::load(&m, &r)?);
            }
        }
        self.one.load(part)
    }
}
