//! A part's calibration as the render workers use it — what `glint calibrate bsdf` and
//! `glint calibrate response` wrote — from files, or the one shipped with Glint
//! (`assets/calibration/`, made by the commands in its README).

use std::path::Path;

use glint_geometry::Part;

use crate::material_file::{MaterialFile, MaterialFileError};
use crate::response::{ResponseError, ResponseTable};

/// A fitted material and a calibrated response.
#[derive(Clone, Debug)]
pub struct Calibration {
    /// The part's fitted principled BSDF (`glint calibrate bsdf`).
    pub material: MaterialFile,
    /// The camera's response g and g⁻¹ (eq 13; `glint calibrate response`).
    pub response: ResponseTable,
}

/// Why a calibration cannot be had.
#[derive(Debug, thiserror::Error)]
pub enum CalibrationFileError {
    /// The material file could not be read or is invalid; the error names the file.
    #[error(transparent)]
    Material(#[from] MaterialFileError),
    /// The response file could not be read or is invalid; the error names the file.
    #[error(transparent)]
    Response(#[from] ResponseError),
    /// Only one of the material and response files was given: pass both, or neither to use
    /// the shipped calibration.
    #[error("--material and --response go together")]
    OnlyOne,
}

/// The shipped calibration of `part`: its `material.json` and `response.json` as text.
fn shipped_text(part: Part) -> (&'static str, &'static str) {
    macro_rules! shipped {
        ($dir:literal) => {
            (
                include_str!(concat!(
                    "../../../assets/calibration/",
                    $dir,
                    "/material.json"
                )),
                include_str!(concat!(
                    "../../../assets/calibration/",
                    $dir,
                    "/response.json"
                )),
            )
        };
    }
    match part {
        Part::EyeBolt => shipped!("eye-bolt"),
        Part::TubeFitting => shipped!("tube-fitting"),
        Part::ChromeScrew => shipped!("chrome-screw"),
        Part::Gear => shipped!("gear"),
        Part::Zigzag => shipped!("zigzag"),
    }
}

impl Calibration {
    /// Reads and validates a material file and a response file.
    pub fn load(material: &Path, response: &Path) -> Result<Self, CalibrationFileError> {
        Ok(Self {
            material: MaterialFile::load(material)?,
            response: ResponseTable::load(response)?,
        })
    }

    /// From `material`/`response` files when given (both), else the calibration shipped for
    /// `part`; the error says how to provide one.
    pub fn from_files_or_embedded(
        part: Part,
        material: Option<&Path>,
        response: Option<&Path>,
    ) -> Result<Self, CalibrationFileError> {
        match (material, response) {
            (Some(m), Some(r)) => Self::load(m, r),
            (None, None) => Self::embedded(part),
            _ => Err(CalibrationFileError::OnlyOne),
        }
    }

    /// The calibration shipped with Glint for `part` (`assets/calibration/README.md` says how
    /// each was made). The files are checked as any other; an error here is a broken build.
    pub fn embedded(part: Part) -> Result<Self, CalibrationFileError> {
        let (material, response) = shipped_text(part);
        let origin = Path::new("assets/calibration").join(part.name());
        Ok(Self {
            material: MaterialFile::parse(material, &origin.join("material.json"))?,
            response: ResponseTable::parse(response, &origin.join("response.json"))?,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_part_has_a_valid_shipped_calibration_and_files_go_in_pairs() {
        for part in Part::ALL {
            let shipped = Calibration::embedded(part).unwrap();
            assert!(shipped.material.radiometric_scale().is_some(), "{part}");
            assert!(shipped.material.params().is_ok(), "{part}");
        }
        let e = Calibration::from_files_or_embedded(Part::Zigzag, Some(Path::new("m")), None)
            .unwrap_err();
        assert!(matches!(e, CalibrationFileError::OnlyOne));
    }
}
