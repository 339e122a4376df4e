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
    /// No files were given and no calibration is shipped for this part (the part's display
    /// name): calibrate it and pass both files.
    #[error(
        "rendering the {0} needs its calibrated material and response: only the Zigzag's are \
         embedded; pass --material and --response (from glint calibrate bsdf and glint \
         calibrate response)"
    )]
    NoneShipped(&'static str),
}

const ZIGZAG_MATERIAL: &str = include_str!("../../../assets/calibration/zigzag/material.json");
const ZIGZAG_RESPONSE: &str = include_str!("../../../assets/calibration/zigzag/response.json");

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
            (None, None) => Self::embedded(part)
                .ok_or(CalibrationFileError::NoneShipped(part.display_name()))?,
            _ => Err(CalibrationFileError::OnlyOne),
        }
    }

    /// The calibration shipped with Glint for `part`, if there is one: today the Zigzag's.
    pub fn embedded(part: Part) -> Option<Result<Self, CalibrationFileError>> {
        (part == Part::Zigzag).then(|| {
            let origin = Path::new("assets/calibration/zigzag");
            Ok(Self {
                material: MaterialFile::parse(ZIGZAG_MATERIAL, &origin.join("material.json"))?,
                response: ResponseTable::parse(ZIGZAG_RESPONSE, &origin.join("response.json"))?,
            })
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_zigzag_calibration_is_shipped_and_others_say_how_to_get_one() {
        let zigzag = Calibration::embedded(Part::Zigzag).unwrap().unwrap();
        assert!(zigzag.material.radiometric_scale().is_some());
        assert!(Calibration::embedded(Part::Gear).is_none());
        let e = Calibration::from_files_or_embedded(Part::Gear, None, None).unwrap_err();
        assert!(e.to_string().contains("--material and --response"), "{e}");
        let e = Calibration::from_files_or_embedded(Part::Zigzag, Some(Path::new("m")), None)
            .unwrap_err();
        assert!(matches!(e, CalibrationFileError::OnlyOne));
    }
}
