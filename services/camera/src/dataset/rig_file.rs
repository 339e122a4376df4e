//! Glint's hardware files beside a scene: `glint/rig.json`, the SLI rig as calibration-known
//! hardware (what a real camera's factory calibration gives), and `glint/gt_sensor.json`, the
//! simulator's ground-truth sensor (evaluation only: calibration must not read it).
//!
//! `rig.json`, lengths in metres, pixels in Glint's convention (pixel `(u, v)`'s centre at
//! `(u + 0.5, v + 0.5)`; OpenCV/BOP `cx` = Glint `cx` − 0.5):
//!
//! ```json
//! {
//!   "pixel_convention": "...",
//!   "left_intrinsics": {"width_px": 1280, "height_px": 1024, "fx_px": 1083.1, "fy_px": 1083.1, "cx_px": 640, "cy_px": 512},
//!   "baseline_m": 0.10118,
//!   "t_left_right": {"translation_m": [0.10118, 0, 0], "quaternion_wxyz": [1, 0, 0, 0]},
//!   "t_left_projector": {"translation_m": [0.05059, 0, 0], "quaternion_wxyz": [1, 0, 0, 0]},
//!   "projector_intrinsics": {...},
//!   "projector_intensity_w_per_sr": 1.0
//! }
//! ```
//! The pair is rectified: the right camera has the left's intrinsics and sits at `+baseline`
//! along the left camera's x axis (`t_left_right`, written for readers that want it).

use std::path::Path;

use glint_geometry::camera::{PinholeIntrinsics, StereoRig};
use glint_render::rig::SliRig;
use glint_render::sensor::Sensor;
use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion};
use serde_json::json;

use super::error::DatasetError;
use super::json::{JsonNode, json_encode_error, read_json_as, read_json_file, write_pretty_json};

/// What `pixel_convention` says in `rig.json`.
pub const GLINT_PIXEL_CONVENTION: &str = "pixel (u, v) has its centre at (u + 0.5, v + 0.5); \
     OpenCV/BOP cx = cx_px - 0.5, cy = cy_px - 0.5";

/// Largest |‖q‖ − 1| accepted for a quaternion read from `rig.json`.
const QUATERNION_NORM_TOLERANCE: f64 = 1e-6;

/// `k` as a JSON value for the file at `path`.
fn intrinsics_json(path: &Path, k: &PinholeIntrinsics) -> Result<serde_json::Value, DatasetError> {
    serde_json::to_value(k).map_err(json_encode_error(path))
}

fn pose_json(t: &Isometry3<f64>) -> serde_json::Value {
    let q = t.rotation.quaternion();
    json!({
        "translation_m": t.translation.vector.as_slice(),
        "quaternion_wxyz": [q.w, q.i, q.j, q.k],
    })
}

/// Writes `rig` as `rig.json` at `path`, atomically.
pub fn write_rig_json(path: &Path, rig: &SliRig) -> Result<(), DatasetError> {
    let left_intrinsics = intrinsics_json(path, &rig.stereo.intrinsics)?;
    let projector_intrinsics = intrinsics_json(path, &rig.projector_intrinsics)?;
    let value = json!({
        "pixel_convention": GLINT_PIXEL_CONVENTION,
        "left_intrinsics": left_intrinsics,
        "baseline_m": rig.stereo.baseline_m,
        "t_left_right": pose_json(&Isometry3::translation(rig.stereo.baseline_m, 0.0, 0.0)),
        "t_left_projector": pose_json(&rig.t_left_projector),
        "projector_intrinsics": projector_intrinsics,
        "projector_intensity_w_per_sr": rig.projector_intensity_w_per_sr,
    });
    write_pretty_json(path, &value)
}

fn parse_intrinsics(node: &JsonNode<'_>) -> Result<PinholeIntrinsics, DatasetError> {
    let size = |key: &str| node.field(key)?.integer::<u32>();
    let number = |key: &str| node.field(key)?.f64();
    PinholeIntrinsics::new(
        size("width_px")?,
        size("height_px")?,
        number("fx_px")?,
        number("fy_px")?,
        number("cx_px")?,
        number("cy_px")?,
    )
    .map_err(|error| node.error(format!("unusable intrinsics: {error}")))
}

fn parse_pose(node: &JsonNode<'_>) -> Result<Isometry3<f64>, DatasetError> {
    let t = node.field("translation_m")?.f64_array::<3>()?;
    let q_node = node.field("quaternion_wxyz")?;
    let [w, x, y, z] = q_node.f64_array::<4>()?;
    let q = Quaternion::new(w, x, y, z);
    let norm = q.norm();
    if (norm - 1.0).abs() > QUATERNION_NORM_TOLERANCE {
        return Err(q_node.error(format!(
            "not a unit quaternion: its norm is {norm} (within {QUATERNION_NORM_TOLERANCE:e} of 1 \
             required; the order is w, x, y, z)"
        )));
    }
    Ok(Isometry3::from_parts(
        Translation3::new(t[0], t[1], t[2]),
        UnitQuaternion::new_normalize(q),
    ))
}

/// Reads a `rig.json`; errors name the file and the key.
pub fn read_rig_json(path: &Path) -> Result<SliRig, DatasetError> {
    let value = read_json_file(path)?;
    let root = JsonNode::root(path, &value);
    let intrinsics = parse_intrinsics(&root.field("left_intrinsics")?)?;
    let baseline_node = root.field("baseline_m")?;
    let stereo = StereoRig::new(intrinsics, baseline_node.f64()?)
        .map_err(|error| baseline_node.error(error.to_string()))?;
    let intensity_node = root.field("projector_intensity_w_per_sr")?;
    let intensity = intensity_node.f64()?;
    if intensity <= 0.0 {
        return Err(intensity_node.error(format!("{intensity} W/sr must be positive")));
    }
    Ok(SliRig {
        stereo,
        t_left_projector: parse_pose(&root.field("t_left_projector")?)?,
        projector_intrinsics: parse_intrinsics(&root.field("projector_intrinsics")?)?,
        projector_intensity_w_per_sr: intensity as f32,
    })
}

/// Writes the ground-truth sensor as `gt_sensor.json` at `path`, atomically.
pub fn write_gt_sensor_json(path: &Path, sensor: &Sensor) -> Result<(), DatasetError> {
    write_pretty_json(path, sensor)
}

/// Reads a `gt_sensor.json` (for evaluating a calibration against the truth).
pub fn read_gt_sensor_json(path: &Path) -> Result<Sensor, DatasetError> {
    read_json_as(path)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rig_and_sensor_round_trip_and_bad_fields_are_named() {
        let dir = tempfile::tempdir().unwrap();
        let mut rig = SliRig::ensenso_n35().resized(640, 512).unwrap();
        rig.t_left_projector = Isometry3::new(
            nalgebra::Vector3::new(0.05, 0.001, -0.002),
            nalgebra::Vector3::new(0.01, -0.02, 0.003),
        );
        let path = dir.path().join("rig.json");
        write_rig_json(&path, &rig).unwrap();
        let back = read_rig_json(&path).unwrap();
        assert_eq!(back.stereo, rig.stereo);
        assert_eq!(back.projector_intrinsics, rig.projector_intrinsics);
        assert_eq!(
            back.projector_intensity_w_per_sr,
            rig.projector_intensity_w_per_sr
        );
        let dt = back.t_left_projector.inverse() * rig.t_left_projector;
        assert!(dt.translation.vector.norm() < 1e-12 && dt.rotation.angle() < 1e-9);

        let text = std::fs::read_to_string(&path).unwrap();
        let broken = text.replacen("\"fx_px\"", "\"fx\"", 1);
        std::fs::write(&path, broken).unwrap();
        let err = read_rig_json(&path).unwrap_err();
        assert_eq!(err.key(), Some("/left_intrinsics/fx_px"), "{err}");
        let mut value: serde_json::Value = serde_json::from_str(&text).unwrap();
        value["t_left_projector"]["quaternion_wxyz"] = json!([1.0, 0.1, 0.0, 0.0]);
        std::fs::write(&path, value.to_string()).unwrap();
        let err = read_rig_json(&path).unwrap_err();
        assert_eq!(
            err.key(),
            Some("/t_left_projector/quaternion_wxyz"),
            "{err}"
        );

        let sensor_path = dir.path().join("gt_sensor.json");
        let sensor = Sensor::default();
        write_gt_sensor_json(&sensor_path, &sensor).unwrap();
        assert_eq!(read_gt_sensor_json(&sensor_path).unwrap(), sensor);
        std::fs::write(&sensor_path, "{\"exposure_s\": 1}").unwrap();
        let err = read_gt_sensor_json(&sensor_path).unwrap_err().to_string();
        assert!(err.contains("gt_sensor.json"), "{err}");
    }
}
