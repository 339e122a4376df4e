//! `glint/reference_surface.json`: the bin the parts lie in, as known equipment of the
//! calibration set-up — its geometry (metres, world frame = the bin's frame, floor at z = 0) and
//! the principled parameters of its surface, a reference of known reflectance. The BSDF
//! calibration needs it because Debevec–Malik recovers exposure only up to a factor: the bin
//! floor's rendered radiance against its measured relative radiance fixes that factor. A real
//! set-up would measure the reference once (a grey card, a painted tray); the mock camera
//! writes what it renders the bin with.
//!
//! ```json
//! {
//!   "surface": "bin",
//!   "bin": {"inner_size_m": [0.24, 0.18], "wall_height_m": 0.08, "wall_thickness_m": 0.005},
//!   "material": {"base_color": 0.35, "metallic": 0.0, ...every name of PrincipledParams::NAMES}
//! }
//! ```

use std::path::Path;

use glint_render::bsdf::{PARAMETER_COUNT, PrincipledParams};
use serde_json::json;

use super::error::DatasetError;
use super::json::{JsonNode, read_json_file, write_pretty_json};
use crate::bin::BinSpec;

/// The reference surface: the bin and its known material.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ReferenceSurface {
    /// The bin's geometry, metres.
    pub bin: BinSpec,
    /// The principled BSDF parameters of the bin's surface, each in [0, 1].
    pub material: PrincipledParams<f32>,
}

/// Writes `reference` as `reference_surface.json` at `path`, atomically.
pub fn write_reference_surface_json(
    path: &Path,
    reference: &ReferenceSurface,
) -> Result<(), DatasetError> {
    let material: serde_json::Map<String, serde_json::Value> = PrincipledParams::<f32>::NAMES
        .iter()
        .zip(reference.material.to_array())
        .map(|(name, v)| (name.to_string(), json!(v)))
        .collect();
    let b = &reference.bin;
    let value = json!({
        "surface": "bin",
        "bin": {
            "inner_size_m": b.inner_size_m,
            "wall_height_m": b.wall_height_m,
            "wall_thickness_m": b.wall_thickness_m,
        },
        "material": material,
    });
    write_pretty_json(path, &value)
}

/// Reads a `reference_surface.json`; errors name the file and the key (a missing parameter,
/// a value outside [0, 1], a non-positive bin size).
pub fn read_reference_surface_json(path: &Path) -> Result<ReferenceSurface, DatasetError> {
    let value = read_json_file(path)?;
    let root = JsonNode::root(path, &value);
    let surface = root.field("surface")?;
    if surface.str()? != "bin" {
        return Err(surface.error(format!(
            "{:?}: only the bin (\"bin\") is supported as reference surface",
            surface.str()?
        )));
    }
    let bin_node = root.field("bin")?;
    let positive = |key: &str| -> Result<f64, DatasetError> {
        let node = bin_node.field(key)?;
        let v = node.f64()?;
        if v > 0.0 {
            Ok(v)
        } else {
            Err(node.error(format!("{v} m must be positive")))
        }
    };
    let size_node = bin_node.field("inner_size_m")?;
    let inner_size_m = size_node.f64_array::<2>()?;
    if inner_size_m.iter().any(|&v| v <= 0.0) {
        return Err(size_node.error(format!("{inner_size_m:?} m must be positive")));
    }
    let bin = BinSpec {
        inner_size_m,
        wall_height_m: positive("wall_height_m")?,
        wall_thickness_m: positive("wall_thickness_m")?,
    };
    let material_node = root.field("material")?;
    let mut values = [0f32; PARAMETER_COUNT];
    for (v, name) in values.iter_mut().zip(PrincipledParams::<f32>::NAMES) {
        let node = material_node.field(name)?;
        let x = node.f64()?;
        if !(0.0..=1.0).contains(&x) {
            return Err(node.error(format!("{x} must lie in [0, 1]")));
        }
        *v = x as f32;
    }
    if let Some((unknown, node)) = material_node
        .entries()?
        .into_iter()
        .find(|(k, _)| !PrincipledParams::<f32>::NAMES.contains(k))
    {
        return Err(node.error(format!("unknown principled parameter {unknown:?}")));
    }
    Ok(ReferenceSurface {
        bin,
        material: PrincipledParams::from_array(values),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reference_round_trips_and_bad_fields_are_named() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("reference_surface.json");
        let reference = ReferenceSurface {
            bin: BinSpec::default(),
            material: crate::materials::bin(),
        };
        write_reference_surface_json(&path, &reference).unwrap();
        assert_eq!(read_reference_surface_json(&path).unwrap(), reference);

        let good: serde_json::Value =
            serde_json::from_slice(&std::fs::read(&path).unwrap()).unwrap();
        for (key, bad) in [
            ("/material/roughness", json!(1.5)),
            ("/bin/wall_height_m", json!(0.0)),
            ("/surface", json!("floor")),
        ] {
            let mut value = good.clone();
            *value.pointer_mut(key).unwrap() = bad;
            std::fs::write(&path, value.to_string()).unwrap();
            let err = read_reference_surface_json(&path).unwrap_err();
            assert_eq!(err.key(), Some(key), "{err}");
            assert!(err.to_string().contains("reference_surface.json"), "{err}");
        }
        let mut value = good.clone();
        value["material"]
            .as_object_mut()
            .unwrap()
            .remove("metallic");
        std::fs::write(&path, value.to_string()).unwrap();
        let err = read_reference_surface_json(&path).unwrap_err();
        assert_eq!(err.key(), Some("/material/metallic"), "{err}");
    }
}
