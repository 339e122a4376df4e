//! The camera's error model on one part, as a session's refinement and its planner use it:
//! the depth bias neighbouring pixels share ([`crate::correlated_error`]) and the pose error
//! all of one view's points share ([`crate::view_bias`]). Both describe the camera on the
//! part, not a result: `glint eval refine` measures them on tuning scenes at known poses and
//! writes one file per part (`DIR/pose_error/<part>.json`); Glint ships the built-in parts'
//! in `assets/calibration/<part>/pose_error.json`.
//!
//! With the model, a refinement's information is what survives both errors
//! (`view_bias`'s `I M⁺ I` over the views' correlated-error information), so its entropy —
//! and a session's entropy threshold — means what it says; without it, eq 18's independent
//! pixels claim hundreds of times too much (Table I's NEES).
//!
//! File format (JSON): `format` `"glint-pose-error/1"`, the part's name, `cell_m` and
//! `bias_sigma_m` (metres), `view_bias_covariance_v` (B, 6×6 rows, view frame, translation in
//! metres first, then rotation in radians) and what it was measured on.

use std::path::{Path, PathBuf};

use glint_geometry::Part;
use glint_geometry::io::{AtomicWriteError, write_file_atomically};
use glint_geometry::sdf::SdfGrid;
use nalgebra::{Isometry3, Matrix6};

use crate::correlated_error::{CorrelatedDepthError, information_with_correlated_error};
use crate::points::DepthPoint;
use crate::refine::SdfRefineConfig;
use crate::view_bias::{ViewInformation, ViewPoseBias};

/// The `format` field of a pose error file.
pub const POSE_ERROR_FORMAT: &str = "glint-pose-error/1";

/// The largest cell edge and bias σ a model accepts, metres: beyond them the numbers are not
/// a camera's (a unit slip, mm for m).
const MAX_CELL_M: f64 = 1.0;
const MAX_BIAS_SIGMA_M: f64 = 0.05;

/// The camera's depth and per-view pose errors on one part.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(try_from = "ModelRecord", into = "ModelRecord")]
pub struct PoseErrorModel {
    /// The depth bias one view's points share within a world cell (finite cell).
    pub depth_error: CorrelatedDepthError,
    /// The pose error one view's points share.
    pub view_bias: ViewPoseBias,
}

/// Why a pose error model or its file is unusable.
#[derive(Debug, thiserror::Error)]
pub enum PoseErrorModelError {
    /// The file cannot be read.
    #[error("{}: cannot read the pose error file: {error}", path.display())]
    Read {
        /// The file.
        path: PathBuf,
        /// Why.
        error: std::io::Error,
    },
    /// The file is not a pose error file's JSON.
    #[error("{}: not a pose error file ({message})", path.display())]
    Malformed {
        /// The file.
        path: PathBuf,
        /// What the parser said.
        message: String,
    },
    /// A value is out of range.
    #[error(transparent)]
    Invalid(#[from] InvalidModel),
    /// The file could not be written.
    #[error(transparent)]
    Write(#[from] AtomicWriteError),
}

/// A model value out of range: fix `field` (`cell_m`, `view_bias_covariance_v`).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{field}: {message}")]
pub struct InvalidModel {
    /// The offending field.
    pub field: &'static str,
    /// What is wrong with it.
    pub message: String,
}

fn invalid(field: &'static str, message: impl Into<String>) -> InvalidModel {
    InvalidModel {
        field,
        message: message.into(),
    }
}

impl PoseErrorModel {
    /// Checks every value; the error names the field (`cell_m`, `bias_sigma_m`,
    /// `view_bias_covariance_v`).
    pub fn validate(&self) -> Result<(), InvalidModel> {
        let cell = self.depth_error.cell_m;
        if !(cell.is_finite() && cell > 0.0 && cell <= MAX_CELL_M) {
            return Err(invalid(
                "cell_m",
                format!("is {cell}; a cell edge in metres, above 0 and at most {MAX_CELL_M}"),
            ));
        }
        let sigma = self.depth_error.bias_sigma_m;
        if !(sigma.is_finite() && (0.0..=MAX_BIAS_SIGMA_M).contains(&sigma)) {
            return Err(invalid(
                "bias_sigma_m",
                format!("is {sigma}; a depth bias σ in metres, 0 to {MAX_BIAS_SIGMA_M}"),
            ));
        }
        let b = &self.view_bias.covariance_v;
        let scale = b.amax();
        if !b.iter().all(|v| v.is_finite()) || (b - b.transpose()).amax() > 1e-9 * scale {
            return Err(invalid(
                "view_bias_covariance_v",
                "must be finite and symmetric (a covariance)",
            ));
        }
        let lowest = b.symmetric_eigenvalues().min();
        if lowest < -1e-9 * scale {
            return Err(invalid(
                "view_bias_covariance_v",
                format!("has a negative eigenvalue ({lowest:e}); a covariance is PSD"),
            ));
        }
        Ok(())
    }

    /// View `points`' information under the depth error at `t_o_w` and where its camera
    /// (`t_w_c`, left camera → world) looked from: one entry of [`Self::information`].
    pub fn view_information(
        &self,
        sdf: &SdfGrid,
        points: &[DepthPoint],
        t_o_w: &Isometry3<f64>,
        t_w_c: &Isometry3<f64>,
        config: &SdfRefineConfig,
    ) -> ViewInformation {
        ViewInformation {
            information: information_with_correlated_error(
                sdf,
                &[points],
                t_o_w,
                config,
                &self.depth_error,
            ),
            r_o_c: (t_o_w * t_w_c).rotation.to_rotation_matrix(),
        }
    }

    /// The information of a pose refined on `views` under both errors
    /// ([`ViewPoseBias::information`]), refiner's δ coordinates.
    pub fn information(&self, views: &[ViewInformation]) -> Matrix6<f64> {
        self.view_bias.information(views)
    }

    /// The information of a pose `t_o_w` refined on `views` (each view's points and its left
    /// camera → world) under both errors: [`Self::view_information`] per view, then
    /// [`Self::information`].
    pub fn refined_information<'a>(
        &self,
        sdf: &SdfGrid,
        views: impl IntoIterator<Item = (&'a [DepthPoint], Isometry3<f64>)>,
        t_o_w: &Isometry3<f64>,
        config: &SdfRefineConfig,
    ) -> Matrix6<f64> {
        let per_view: Vec<ViewInformation> = views
            .into_iter()
            .map(|(points, t_w_c)| self.view_information(sdf, points, t_o_w, &t_w_c, config))
            .collect();
        self.information(&per_view)
    }

    /// A predicted view's information `information` (eq 21–22, independent pixels) from a
    /// camera whose axes are `r_o_c` in the object frame, as the planner adds it: capped by
    /// the per-view bias (`(I⁻¹ + B_v)⁻¹`, the view's own pose estimate's information).
    pub fn predicted_view_information(
        &self,
        information: &Matrix6<f64>,
        r_o_c: &nalgebra::Rotation3<f64>,
    ) -> Matrix6<f64> {
        self.view_bias.information(&[ViewInformation {
            information: *information,
            r_o_c: *r_o_c,
        }])
    }

    /// [`Self::predicted_view_information`] of a candidate whose left camera → world is
    /// `t_w_c`, for a part believed at `t_w_o`.
    pub fn predicted_candidate_information(
        &self,
        information: &Matrix6<f64>,
        t_w_o: &Isometry3<f64>,
        t_w_c: &Isometry3<f64>,
    ) -> Matrix6<f64> {
        let r_o_c = (t_w_o.inverse() * t_w_c).rotation.to_rotation_matrix();
        self.predicted_view_information(information, &r_o_c)
    }

    /// The model Glint ships for `part`: `assets/calibration/<part>/pose_error.json`, as
    /// `glint eval refine` measured it (that folder's README has the command).
    pub fn shipped(part: Part) -> Result<Self, PoseErrorModelError> {
        macro_rules! shipped {
            ($dir:literal) => {
                (
                    include_str!(concat!(
                        "../../../assets/calibration/",
                        $dir,
                        "/pose_error.json"
                    )),
                    concat!("assets/calibration/", $dir, "/pose_error.json"),
                )
            };
        }
        let (text, origin) = match part {
            Part::EyeBolt => shipped!("eye-bolt"),
            Part::TubeFitting => shipped!("tube-fitting"),
            Part::ChromeScrew => shipped!("chrome-screw"),
            Part::Gear => shipped!("gear"),
            Part::Zigzag => shipped!("zigzag"),
        };
        Self::parse(text, Path::new(origin))
    }

    /// Reads and validates a pose error file.
    pub fn load(path: &Path) -> Result<Self, PoseErrorModelError> {
        let text = std::fs::read_to_string(path).map_err(|error| PoseErrorModelError::Read {
            path: path.to_path_buf(),
            error,
        })?;
        Self::parse(&text, path)
    }

    /// Parses and validates a pose error file's text; `origin` names it in errors.
    pub fn parse(text: &str, origin: &Path) -> Result<Self, PoseErrorModelError> {
        let record: FileRecord =
            serde_json::from_str(text).map_err(|e| PoseErrorModelError::Malformed {
                path: origin.to_path_buf(),
                message: e.to_string(),
            })?;
        if record.format != POSE_ERROR_FORMAT {
            return Err(PoseErrorModelError::Malformed {
                path: origin.to_path_buf(),
                message: format!(
                    "format is {:?}, expected {POSE_ERROR_FORMAT:?}",
                    record.format
                ),
            });
        }
        Self::try_from(record.model)
    }

    /// Writes the model of `part` (its name in files), measured on `measured_on` (which
    /// scenes, how many samples), atomically.
    pub fn save(
        &self,
        path: &Path,
        part: &str,
        measured_on: &str,
    ) -> Result<(), PoseErrorModelError> {
        self.validate()?;
        let record = FileRecord {
            format: POSE_ERROR_FORMAT.to_string(),
            part: part.to_string(),
            measured_on: measured_on.to_string(),
            model: (*self).into(),
        };
        let text =
            serde_json::to_string_pretty(&record).map_err(|e| PoseErrorModelError::Malformed {
                path: path.to_path_buf(),
                message: e.to_string(),
            })?;
        Ok(write_file_atomically(path, text.as_bytes())?)
    }
}

/// The model's fields as files and journals hold them (B as rows).
#[derive(serde::Serialize, serde::Deserialize)]
struct ModelRecord {
    cell_m: f64,
    bias_sigma_m: f64,
    view_bias_covariance_v: [[f64; 6]; 6],
}

#[derive(serde::Serialize, serde::Deserialize)]
struct FileRecord {
    format: String,
    part: String,
    measured_on: String,
    #[serde(flatten)]
    model: ModelRecord,
}

impl TryFrom<ModelRecord> for PoseErrorModel {
    type Error = PoseErrorModelError;
    fn try_from(r: ModelRecord) -> Result<Self, Self::Error> {
        let model = Self {
            depth_error: CorrelatedDepthError {
                cell_m: r.cell_m,
                bias_sigma_m: r.bias_sigma_m,
            },
            view_bias: ViewPoseBias {
                covariance_v: Matrix6::from_fn(|i, j| r.view_bias_covariance_v[i][j]),
            },
        };
        model.validate()?;
        Ok(model)
    }
}

impl From<PoseErrorModel> for ModelRecord {
    fn from(m: PoseErrorModel) -> Self {
        let b = &m.view_bias.covariance_v;
        Self {
            cell_m: m.depth_error.cell_m,
            bias_sigma_m: m.depth_error.bias_sigma_m,
            view_bias_covariance_v: std::array::from_fn(|i| std::array::from_fn(|j| b[(i, j)])),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn model() -> PoseErrorModel {
        let mut b =
            Matrix6::from_diagonal(&nalgebra::Vector6::new(1e-7, 2e-7, 4e-7, 1e-5, 2e-5, 3e-5));
        b[(0, 4)] = 3e-7;
        b[(4, 0)] = 3e-7;
        PoseErrorModel {
            depth_error: CorrelatedDepthError {
                cell_m: 2e-3,
                bias_sigma_m: 0.583e-3,
            },
            view_bias: ViewPoseBias { covariance_v: b },
        }
    }

    /// Every shipped model parses and is a camera's: B's translation σ between 0.05 and 5 mm
    /// and rotation σ between 0.05 and 5° on every axis (the measured 0.2–1.2 mm, 0.2–2.2°,
    /// with room), the 2 mm cell and its sub-millimetre bias.
    #[test]
    fn the_shipped_models_are_cameras() {
        for part in Part::ALL {
            let m = PoseErrorModel::shipped(part).unwrap();
            let (t, r) = m.view_bias.sigmas();
            for s in t {
                assert!((0.05e-3..5e-3).contains(&s), "{part:?}: σ_t {s}");
            }
            for s in r {
                assert!(
                    (0.05f64.to_radians()..5f64.to_radians()).contains(&s),
                    "{part:?}: σ_r {s}"
                );
            }
            assert!(m.depth_error.bias_sigma_m < 1e-3, "{part:?}");
        }
    }

    #[test]
    fn a_file_round_trips_to_the_bit() {
        let dir = std::env::temp_dir().join(format!("glint-pose-error-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("gear.json");
        model().save(&path, "gear", "test").unwrap();
        assert_eq!(PoseErrorModel::load(&path).unwrap(), model());
        // The journal's form (serde) round-trips too.
        let json = serde_json::to_string(&model()).unwrap();
        assert_eq!(
            serde_json::from_str::<PoseErrorModel>(&json).unwrap(),
            model()
        );
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn bad_files_and_values_name_what_is_wrong() {
        let origin = Path::new("x.json");
        let field = |text: &str| match PoseErrorModel::parse(text, origin) {
            Err(PoseErrorModelError::Invalid(e)) => e.field,
            other => panic!("{other:?}"),
        };
        let good = {
            let record = FileRecord {
                format: POSE_ERROR_FORMAT.into(),
                part: "gear".into(),
                measured_on: "test".into(),
                model: model().into(),
            };
            serde_json::to_value(&record).unwrap()
        };
        let with = |key: &str, value: serde_json::Value| {
            let mut v = good.clone();
            v[key] = value;
            v.to_string()
        };
        assert!(PoseErrorModel::parse(&good.to_string(), origin).is_ok());
        assert_eq!(field(&with("cell_m", 0.0.into())), "cell_m");
        assert_eq!(field(&with("cell_m", 2.0.into())), "cell_m");
        assert_eq!(field(&with("bias_sigma_m", (-1e-3).into())), "bias_sigma_m");
        let mut asymmetric = good["view_bias_covariance_v"].clone();
        asymmetric[0][4] = 1e-5.into();
        assert_eq!(
            field(&with("view_bias_covariance_v", asymmetric)),
            "view_bias_covariance_v"
        );
        let mut negative = good["view_bias_covariance_v"].clone();
        negative[2][2] = (-1e-5).into();
        assert_eq!(
            field(&with("view_bias_covariance_v", negative)),
            "view_bias_covariance_v"
        );
        assert!(matches!(
            PoseErrorModel::parse(&with("format", "other/1".into()), origin),
            Err(PoseErrorModelError::Malformed { .. })
        ));
        assert!(matches!(
            PoseErrorModel::parse("{", origin),
            Err(PoseErrorModelError::Malformed { .. })
        ));
        assert!(matches!(
            PoseErrorModel::load(Path::new("/nonexistent/pose_error.json")),
            Err(PoseErrorModelError::Read { .. })
        ));
    }

    /// A predicted view's information under the model is the information of a Gaussian with
    /// covariance `I⁻¹ + B_v` (the view's own estimate), checked against the closed form.
    #[test]
    fn a_predicted_view_is_capped_by_its_bias() {
        let m = model();
        let information =
            Matrix6::from_diagonal(&nalgebra::Vector6::new(1e8, 2e8, 5e7, 1e6, 3e5, 2e6));
        let r_o_c = nalgebra::Rotation3::from_euler_angles(0.3, -0.2, 1.1);
        let got = m.predicted_view_information(&information, &r_o_c);
        let ad = glint_geometry::se3::adjoint(&Isometry3::from_parts(
            nalgebra::Translation3::identity(),
            r_o_c.into(),
        ));
        let b_o = ad * m.view_bias.covariance_v * ad.transpose();
        let want = (information.try_inverse().unwrap() + b_o)
            .try_inverse()
            .unwrap();
        let rel = (got - want).amax() / want.amax();
        assert!(rel < 1e-9, "relative difference {rel:e}");
    }
}
