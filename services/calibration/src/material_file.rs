//! Material files, one type each: the fitted material `glint calibrate bsdf` writes (and the
//! uncertainty predictor reads), and the mock camera's ground-truth materials beside a capture
//! (evaluation only).
//!
//! ```json
//! { "format": "glint-material/1",
//!   "params": { "base_color": 0.78, "metallic": 1.0, "roughness": 0.16, ... },
//!   ... provenance of the fit (scene, views, loss, ...) ... }
//! ```

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use glint_geometry::io::write_file_atomically;
use glint_render::bsdf::PrincipledParams;
use serde::{Deserialize, Serialize};

use crate::material_map::{MaterialMapError, params_from_map, params_to_map};

/// The `format` of a fitted material file.
pub const MATERIAL_FORMAT: &str = "glint-material/1";

/// Why a material file could not be read or written.
#[derive(Debug, thiserror::Error)]
pub enum MaterialFileError {
    // The reason is in the message, not a `source`: a chain printed whole would say it twice.
    /// The file could not be read (missing, unreadable): check the path.
    #[error("cannot read {}: {error}", path.display())]
    Read {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        error: std::io::Error,
    },
    /// The file could not be written (its folder is missing or not writable).
    #[error(transparent)]
    Write(#[from] glint_geometry::io::AtomicWriteError),
    /// The text is not JSON of the expected shape (or could not be encoded, when writing).
    #[error("{}: not a material file: {problem}", path.display())]
    Malformed {
        /// The file, or where the text came from.
        path: PathBuf,
        /// What the JSON parser reported.
        problem: String,
    },
    /// The `format` is not [`MATERIAL_FORMAT`]: not a fitted material file, or another version.
    #[error("{}: format {found:?}, expected {MATERIAL_FORMAT:?}", path.display())]
    Format {
        /// The file, or where the text came from.
        path: PathBuf,
        /// The file's `format`.
        found: String,
    },
    /// A parameter map is incomplete, has an unknown name or a value out of range.
    #[error("{}: {source}", path.display())]
    Params {
        /// The file, or where the text came from.
        path: PathBuf,
        /// What is wrong with the map, naming it.
        #[source]
        source: MaterialMapError,
    },
}

/// A fitted material: its principled parameters and, free-form, how it was obtained.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct MaterialFile {
    /// The file format, [`MATERIAL_FORMAT`].
    pub format: String,
    /// Every name of [`PrincipledParams::NAMES`], each in [0, 1].
    pub params: BTreeMap<String, f32>,
    /// Provenance (scene, views, loss, timings ...), kept as written.
    #[serde(flatten)]
    pub provenance: serde_json::Map<String, serde_json::Value>,
}

impl MaterialFile {
    /// A material file of `params` with the fit's `provenance`, in format [`MATERIAL_FORMAT`].
    pub fn new(
        params: &PrincipledParams<f32>,
        provenance: serde_json::Map<String, serde_json::Value>,
    ) -> Self {
        Self {
            format: MATERIAL_FORMAT.into(),
            params: params_to_map(params),
            provenance,
        }
    }

    /// Reads and validates `path`: the format, every parameter present and in range.
    pub fn load(path: &Path) -> Result<Self, MaterialFileError> {
        Self::parse(&read_text(path)?, path)
    }

    /// Checks and reads the JSON text of a material file; `origin` names where it came from in
    /// errors (a file, or an embedded default).
    pub fn parse(text: &str, origin: &Path) -> Result<Self, MaterialFileError> {
        let path = origin;
        let file: Self = from_json(text, path)?;
        if file.format != MATERIAL_FORMAT {
            return Err(MaterialFileError::Format {
                path: path.into(),
                found: file.format,
            });
        }
        validated(path, &file.params, "params")?;
        Ok(file)
    }

    /// Writes the file atomically (a reader never sees half of it).
    pub fn save(&self, path: &Path) -> Result<(), MaterialFileError> {
        write_json(path, self)
    }

    /// The fit's radiometric scale (relative radiance-map units per W·sr⁻¹·m⁻²): the median
    /// of its views' `per_view[].radiometric_scale`, if the provenance holds any.
    pub fn radiometric_scale(&self) -> Option<f64> {
        let mut scales: Vec<f64> = self
            .provenance
            .get("per_view")?
            .as_array()?
            .iter()
            .filter_map(|v| v.get("radiometric_scale")?.as_f64())
            .filter(|s| s.is_finite() && *s > 0.0)
            .collect();
        scales.sort_by(f64::total_cmp);
        scales.get(scales.len() / 2).copied()
    }

    /// The principled parameters, validated.
    pub fn params(&self) -> Result<PrincipledParams<f32>, MaterialMapError> {
        params_from_map(&self.params, "params")
    }
}

/// The mock camera's ground truth beside a capture (`glint/gt_materials.json`): the part's and
/// the bin's materials. Evaluation only: estimators and predictors never read it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct GroundTruthMaterials {
    /// A warning for readers of the file: ground truth, for evaluation only.
    pub note: String,
    /// The part's name.
    pub part: String,
    /// The part's principled parameters (every name of [`PrincipledParams::NAMES`], each in
    /// [0, 1]).
    pub part_material: BTreeMap<String, f32>,
    /// The bin's principled parameters (every name of [`PrincipledParams::NAMES`], each in
    /// [0, 1]).
    pub bin_material: BTreeMap<String, f32>,
}

impl GroundTruthMaterials {
    /// The ground truth of part `part_name` with materials `part` and `bin`.
    pub fn new(part_name: &str, part: PrincipledParams<f32>, bin: PrincipledParams<f32>) -> Self {
        Self {
            note: "ground truth of the simulator, for evaluation only; estimators must not read it"
                .into(),
            part: part_name.into(),
            part_material: params_to_map(&part),
            bin_material: params_to_map(&bin),
        }
    }

    /// Reads `path` and validates both parameter maps.
    pub fn load(path: &Path) -> Result<Self, MaterialFileError> {
        let file: Self = from_json(&read_text(path)?, path)?;
        validated(path, &file.part_material, "part_material")?;
        validated(path, &file.bin_material, "bin_material")?;
        Ok(file)
    }

    /// Writes the file atomically (a reader never sees half of it).
    pub fn save(&self, path: &Path) -> Result<(), MaterialFileError> {
        write_json(path, self)
    }

    /// The part's parameters, validated.
    pub fn part_params(&self) -> Result<PrincipledParams<f32>, MaterialMapError> {
        params_from_map(&self.part_material, "part_material")
    }
}

/// The parameter map `field` of the file at `path`, validated.
fn validated(
    path: &Path,
    map: &BTreeMap<String, f32>,
    field: &str,
) -> Result<PrincipledParams<f32>, MaterialFileError> {
    params_from_map(map, field).map_err(|source| MaterialFileError::Params {
        path: path.into(),
        source,
    })
}

fn read_text(path: &Path) -> Result<String, MaterialFileError> {
    std::fs::read_to_string(path).map_err(|error| MaterialFileError::Read {
        path: path.into(),
        error,
    })
}

fn from_json<T: serde::de::DeserializeOwned>(
    text: &str,
    origin: &Path,
) -> Result<T, MaterialFileError> {
    serde_json::from_str(text).map_err(|e| MaterialFileError::Malformed {
        path: origin.into(),
        problem: e.to_string(),
    })
}

fn write_json<T: Serialize>(path: &Path, value: &T) -> Result<(), MaterialFileError> {
    let text = serde_json::to_string_pretty(value).map_err(|e| MaterialFileError::Malformed {
        path: path.into(),
        problem: e.to_string(),
    })?;
    Ok(write_file_atomically(path, text.as_bytes())?)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn gear() -> PrincipledParams<f32> {
        PrincipledParams {
            base_color: 0.78,
            metallic: 1.0,
            roughness: 0.16,
            ..PrincipledParams::default()
        }
    }

    #[test]
    fn files_round_trip_and_keep_their_provenance() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("material.json");
        let mut provenance = serde_json::Map::new();
        provenance.insert("views".into(), serde_json::json!([0, 1]));
        let file = MaterialFile::new(&gear(), provenance);
        file.save(&path).unwrap();
        let read = MaterialFile::load(&path).unwrap();
        assert_eq!(read, file);
        assert_eq!(read.params().unwrap(), gear());
        assert_eq!(read.provenance["views"], serde_json::json!([0, 1]));

        let gt_path = dir.path().join("gt_materials.json");
        let gt = GroundTruthMaterials::new("gear", gear(), PrincipledParams::default());
        gt.save(&gt_path).unwrap();
        assert_eq!(
            GroundTruthMaterials::load(&gt_path)
                .unwrap()
                .part_params()
                .unwrap(),
            gear()
        );
    }

    #[test]
    fn bad_files_name_the_problem() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("m.json");
        let missing = MaterialFile::load(&path).unwrap_err();
        assert!(
            matches!(missing, MaterialFileError::Read { .. }),
            "{missing}"
        );
        std::fs::write(&path, "{ \"format\": ").unwrap();
        let truncated = MaterialFile::load(&path).unwrap_err();
        assert!(
            matches!(truncated, MaterialFileError::Malformed { .. }),
            "{truncated}"
        );
        let mut file = MaterialFile::new(&gear(), serde_json::Map::new());
        file.params.insert("roughness".into(), 1.5);
        file.save(&path).unwrap();
        let out_of_range = MaterialFile::load(&path).unwrap_err();
        assert!(
            out_of_range.to_string().contains("roughness"),
            "{out_of_range}"
        );
        file.params.remove("roughness");
        file.save(&path).unwrap();
        let err = MaterialFile::load(&path).unwrap_err();
        assert!(
            err.to_string().contains("missing parameter \"roughness\""),
            "{err}"
        );
        file.format = "other/2".into();
        file.save(&path).unwrap();
        assert!(matches!(
            MaterialFile::load(&path).unwrap_err(),
            MaterialFileError::Format { .. }
        ));
    }
}
