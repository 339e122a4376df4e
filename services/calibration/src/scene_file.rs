//! `calib_scene.json`: what the BSDF fit knows about a calibration scene — the part and its
//! labelled pose, the bin it lies in, the rig's resolution and poses, and a reference surface of
//! known reflectance that fixes the radiometric scale of the radiance map (Debevec–Malik
//! recovers exposure only up to a factor). The exposure stack lives in `exposure_stack/` beside
//! it. Ground truth (sensor, material) is not in this file.

use std::path::Path;

use glint_render::bsdf::PrincipledParams;
use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion};

/// Format tag of the scene file.
pub const SCENE_FORMAT: &str = "glint-calib-scene/1";

/// A rigid transform as stored: translation in metres, rotation as a unit quaternion (w, x, y, z).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PoseJson {
    pub translation_m: [f64; 3],
    pub rotation_wxyz: [f64; 4],
}

impl PoseJson {
    pub fn from_isometry(t: &Isometry3<f64>) -> Self {
        let q = t.rotation.quaternion();
        Self {
            translation_m: t.translation.vector.into(),
            rotation_wxyz: [q.w, q.i, q.j, q.k],
        }
    }

    /// The transform, or why not (non-finite values, a zero quaternion).
    pub fn to_isometry(&self, field: &str) -> Result<Isometry3<f64>, String> {
        let [w, x, y, z] = self.rotation_wxyz;
        let q = Quaternion::new(w, x, y, z);
        let all_finite = self
            .translation_m
            .iter()
            .chain(&self.rotation_wxyz)
            .all(|v| v.is_finite());
        if !all_finite || q.norm() < 1e-9 {
            return Err(format!(
                "{field}: translation_m and rotation_wxyz must be finite with a non-zero quaternion"
            ));
        }
        let [tx, ty, tz] = self.translation_m;
        Ok(Isometry3::from_parts(
            Translation3::new(tx, ty, tz),
            UnitQuaternion::from_quaternion(q),
        ))
    }
}

/// The scene file.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CalibrationScene {
    pub format: String,
    /// Part name (`eye-bolt`, `tube-fitting`, `chrome-screw`, `gear`, `zigzag`).
    pub part: String,
    /// Object → world of the part (labelled).
    pub t_w_o: PoseJson,
    /// Left camera → world where the exposure stack was taken.
    pub t_w_c: PoseJson,
    /// Left camera → world of a held-out view (evaluation of the fitted material).
    pub held_out_t_w_c: PoseJson,
    /// Camera resolution, pixels (the Ensenso N35's field of view).
    pub resolution: [u32; 2],
    /// The bin floor's principled parameters by name: the reference of known reflectance.
    pub reference_material: std::collections::BTreeMap<String, f32>,
}

impl CalibrationScene {
    pub fn reference(&self) -> Result<PrincipledParams<f32>, String> {
        params_from_map(&self.reference_material, "reference_material")
    }

    pub fn load(path: &Path) -> Result<Self, String> {
        let text = std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))?;
        let scene: Self =
            serde_json::from_str(&text).map_err(|e| format!("{}: {e}", path.display()))?;
        if scene.format != SCENE_FORMAT {
            return Err(format!(
                "{}: format is {:?}, expected {SCENE_FORMAT:?}",
                path.display(),
                scene.format
            ));
        }
        Ok(scene)
    }

    pub fn save(&self, path: &Path) -> Result<(), String> {
        let json = serde_json::to_vec_pretty(self).expect("plain data serialises");
        glint_geometry::io::write_file_atomically(path, &json).map_err(|e| e.to_string())
    }
}

/// Principled parameters as a name → value map (every name of [`PrincipledParams::NAMES`]).
pub fn params_to_map(p: &PrincipledParams<f32>) -> std::collections::BTreeMap<String, f32> {
    PrincipledParams::<f32>::NAMES
        .iter()
        .zip(p.to_array())
        .map(|(n, v)| (n.to_string(), v))
        .collect()
}

/// The inverse of [`params_to_map`], validated; `field` names the map in errors.
pub fn params_from_map(
    map: &std::collections::BTreeMap<String, f32>,
    field: &str,
) -> Result<PrincipledParams<f32>, String> {
    if let Some(unknown) = map
        .keys()
        .find(|k| !PrincipledParams::<f32>::NAMES.contains(&k.as_str()))
    {
        return Err(format!("{field}: unknown parameter {unknown:?}"));
    }
    let mut values = [0f32; glint_render::bsdf::PARAMETER_COUNT];
    for (v, name) in values.iter_mut().zip(PrincipledParams::<f32>::NAMES) {
        *v = *map
            .get(name)
            .ok_or_else(|| format!("{field}: missing parameter {name:?}"))?;
    }
    PrincipledParams::from_array(values)
        .validated()
        .map_err(|e| format!("{field}: {e}"))
}
