//! Object models: `models/obj_XXXXXX.ply` (millimetres) and `models/models_info.json`
//! (diameter, bounding box and symmetries, in millimetres).

use std::collections::{BTreeMap, HashSet};
use std::path::{Path, PathBuf};

use glint_geometry::io::{LoadedMesh, PlyEncoding, read_mesh, write_ply};
use glint_geometry::symmetry::Axis;
use glint_geometry::{LengthUnit, Symmetry, TriMesh};
use nalgebra::{Isometry3, Translation3, Unit, UnitQuaternion, Vector3};
use rayon::prelude::*;
use serde::Serialize;

use crate::dataset::error::{DatasetError, create_directory};
use crate::dataset::json::{JsonNode, read_json_file, write_bop_style_object};
use crate::dataset::transforms::{MM_PER_M, isometry_from_matrix4_mm, matrix4_mm_from_isometry};

/// Meshes with at most this many distinct vertices get their exact diameter (all pairs,
/// O(n²)); larger ones a lower bound from a subsample (see [`mesh_diameter_m`]).
pub const EXACT_DIAMETER_MAX_VERTICES: usize = 20_000;

/// Angle, radians, within which a rotation from a file matches a Glint group element.
const SAME_ROTATION_RAD: f64 = 1e-4;

/// Largest deviation of a unit axis from a coordinate axis that still counts as that axis.
const SAME_AXIS: f64 = 1e-6;

/// `models_info.json`'s entry for one model, in metres.
#[derive(Clone, Debug, PartialEq)]
pub struct ModelInfo {
    /// Largest distance between two vertices, metres (BOP's `diameter`).
    pub diameter_m: f64,
    /// Axis-aligned bounding box in the object frame, metres (BOP's `min_x`..., `size_x`...);
    /// `None` when the file gives none.
    pub bbox: Option<ModelBox>,
    /// The model's symmetries (BOP's `symmetries_discrete`, `symmetries_continuous`).
    pub symmetry: ModelSymmetry,
}

/// An axis-aligned box in the object frame, metres.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ModelBox {
    /// The corner with the smallest coordinates.
    pub min_m: Vector3<f64>,
    /// Extent along x, y and z.
    pub size_m: Vector3<f64>,
}

/// A model's symmetries as BOP lists them, plus the Glint group when Glint wrote the file.
///
/// BOP lists the non-identity discrete symmetries as object-frame transforms
/// `p ↦ R p + t`, and continuous ones as an axis through a point. Glint's [`Symmetry`] is a
/// group of rotations about the object origin; [`ModelSymmetry::to_glint`] recognises the
/// groups Glint can express.
#[derive(Clone, Debug, PartialEq)]
pub struct ModelSymmetry {
    /// `symmetries_discrete`: transforms other than the identity, translation in metres.
    pub discrete: Vec<Isometry3<f64>>,
    /// `symmetries_continuous`.
    pub continuous: Vec<ContinuousSymmetry>,
    /// The group Glint wrote (its keys `glint_symmetry` and `glint_symmetry_tolerance_mm`).
    pub glint: Option<Symmetry>,
}

/// Rotations by any angle about `axis` through the point `offset_m` (object frame, metres).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ContinuousSymmetry {
    /// Direction of the rotation axis, object frame (BOP's `axis`).
    pub axis: Unit<Vector3<f64>>,
    /// A point on the axis, object frame, metres (BOP's `offset`, read from mm).
    pub offset_m: Vector3<f64>,
}

impl ModelSymmetry {
    /// BOP's lists for a Glint group: every element of the finite part but the identity, and
    /// the continuous axis through the origin.
    pub fn from_glint(symmetry: &Symmetry) -> Self {
        Self {
            discrete: symmetry
                .discrete_rotations()
                .iter()
                .skip(1)
                .map(|&rotation| Isometry3::from_parts(Translation3::identity(), rotation))
                .collect(),
            continuous: symmetry
                .continuous_axis()
                .map(|axis| ContinuousSymmetry {
                    axis,
                    offset_m: Vector3::zeros(),
                })
                .into_iter()
                .collect(),
            glint: Some(symmetry.clone()),
        }
    }

    /// The Glint group: the one Glint wrote, or else the one BOP's lists describe, if it is
    /// none, `continuous` about a coordinate axis, or cyclic or dihedral about coordinate
    /// axes. Glint's groups act about the object origin, so translations (discrete) and axis
    /// offsets (continuous) become the group's `tolerance_m` (how far the surface may miss
    /// itself) and must not exceed `max_offset_m`.
    pub fn to_glint(&self, max_offset_m: f64) -> Result<Symmetry, String> {
        if let Some(symmetry) = &self.glint {
            return Ok(symmetry.clone());
        }
        let discrete_offset = self
            .discrete
            .iter()
            .map(|t| t.translation.vector.norm())
            .fold(0.0, f64::max);
        // A rotation by θ about an axis through o moves the origin by up to 2|o⊥|.
        let continuous_offset = self
            .continuous
            .iter()
            .map(|c| 2.0 * (c.offset_m - c.axis.into_inner() * c.axis.dot(&c.offset_m)).norm())
            .fold(0.0, f64::max);
        let tolerance_m = discrete_offset.max(continuous_offset);
        if tolerance_m > max_offset_m {
            return Err(format!(
                "the symmetries are about points {:.3} mm from the object origin, more than the \
                 {:.3} mm allowed; Glint's symmetries are rotations about the origin",
                tolerance_m * MM_PER_M,
                max_offset_m * MM_PER_M
            ));
        }
        let mut group = vec![UnitQuaternion::identity()];
        group.extend(self.discrete.iter().map(|t| t.rotation));
        let symmetry = match self.continuous.as_slice() {
            [] => recognise_discrete(&group)?,
            [continuous] => {
                let axis = coordinate_axis(&continuous.axis).ok_or_else(|| {
                    format!(
                        "the continuous symmetry axis {:?} is not a coordinate axis",
                        continuous.axis.as_slice()
                    )
                })?;
                if group.len() > 1 {
                    return Err(format!(
                        "a continuous symmetry about {axis:?} combined with {} discrete ones has \
                         no Glint symmetry spec",
                        group.len() - 1
                    ));
                }
                Symmetry::continuous(axis)
            }
            several => {
                return Err(format!(
                    "{} continuous symmetry axes (a sphere?) have no Glint symmetry spec",
                    several.len()
                ));
            }
        };
        Ok(symmetry.with_tolerance(tolerance_m))
    }
}

/// The coordinate axis `axis` lies along (either direction).
fn coordinate_axis(axis: &Unit<Vector3<f64>>) -> Option<Axis> {
    [Axis::X, Axis::Y, Axis::Z]
        .into_iter()
        .find(|candidate| axis.dot(&candidate.unit()).abs() > 1.0 - SAME_AXIS)
}

/// The cyclic or dihedral group about coordinate axes whose elements are `group`'s.
fn recognise_discrete(group: &[UnitQuaternion<f64>]) -> Result<Symmetry, String> {
    let order = group.len();
    if order == 1 {
        return Ok(Symmetry::none());
    }
    // z first: BOP's model frames have z up, so a z-axis spec is the natural name of a
    // group that several specs describe (dihedral:z:2:x = dihedral:x:2:y).
    let axes = [Axis::Z, Axis::X, Axis::Y];
    let mut candidates = Vec::new();
    if let Ok(n) = u32::try_from(order) {
        for axis in axes {
            candidates.push(Symmetry::cyclic(axis, n));
            if order.is_multiple_of(2) && order >= 4 {
                for flip in [Axis::X, Axis::Y, Axis::Z]
                    .into_iter()
                    .filter(|&flip| flip != axis)
                {
                    candidates.push(Symmetry::dihedral(axis, n / 2, flip));
                }
            }
        }
    }
    candidates
        .into_iter()
        .find(|candidate| {
            candidate.discrete_order() == order
                && candidate.discrete_rotations().iter().all(|element| {
                    group
                        .iter()
                        .any(|given| given.angle_to(element) < SAME_ROTATION_RAD)
                })
        })
        .ok_or_else(|| {
            format!(
                "the {order} discrete symmetries (with the identity) form none of Glint's groups \
                 (cyclic or dihedral about the object's x, y or z axis)"
            )
        })
}

/// `models_dir/obj_XXXXXX.ply`.
pub fn model_path(models_dir: &Path, obj_id: u32) -> PathBuf {
    models_dir.join(format!("obj_{obj_id:06}.ply"))
}

/// Reads model `obj_id` (millimetres in the file) in metres.
pub fn read_model(models_dir: &Path, obj_id: u32) -> Result<LoadedMesh, DatasetError> {
    Ok(read_mesh(
        &model_path(models_dir, obj_id),
        LengthUnit::Millimetre,
    )?)
}

/// The largest distance between two vertices of `mesh`, metres.
///
/// Exact (all pairs of distinct vertices, O(n²), in parallel) for up to
/// [`EXACT_DIAMETER_MAX_VERTICES`] distinct vertices. Above that, exact over a subsample of
/// that many: the extreme vertices along 13 directions (axes, face and body diagonals) plus
/// evenly strided ones. That is a lower bound, short of the true diameter by at most the
/// spacing of the skipped vertices near the far ends, and never shorter than the largest of
/// the 13 directional extents. 0 for an empty mesh.
pub fn mesh_diameter_m(mesh: &TriMesh) -> f64 {
    let mut seen = HashSet::new();
    let points: Vec<Vector3<f64>> = mesh
        .vertices
        .iter()
        .filter(|p| seen.insert([p.x.to_bits(), p.y.to_bits(), p.z.to_bits()]))
        .map(|p| p.coords.cast::<f64>())
        .collect();
    if points.len() <= EXACT_DIAMETER_MAX_VERTICES {
        return exact_diameter(&points);
    }
    let directions: Vec<Vector3<f64>> = [
        [1, 0, 0],
        [0, 1, 0],
        [0, 0, 1],
        [1, 1, 0],
        [1, -1, 0],
        [1, 0, 1],
        [1, 0, -1],
        [0, 1, 1],
        [0, 1, -1],
        [1, 1, 1],
        [1, 1, -1],
        [1, -1, 1],
        [-1, 1, 1],
    ]
    .iter()
    .map(|d| Vector3::new(d[0] as f64, d[1] as f64, d[2] as f64))
    .collect();
    let mut chosen: Vec<usize> = Vec::with_capacity(EXACT_DIAMETER_MAX_VERTICES);
    for direction in &directions {
        let along = |i: &usize| points[*i].dot(direction);
        let indices = 0..points.len();
        let lowest = indices.clone().min_by(|a, b| along(a).total_cmp(&along(b)));
        let highest = indices.max_by(|a, b| along(a).total_cmp(&along(b)));
        chosen.extend(lowest.into_iter().chain(highest));
    }
    let room = EXACT_DIAMETER_MAX_VERTICES - chosen.len();
    let stride = points.len().div_ceil(room);
    chosen.extend((0..points.len()).step_by(stride));
    chosen.sort_unstable();
    chosen.dedup();
    let subsample: Vec<Vector3<f64>> = chosen.iter().map(|&i| points[i]).collect();
    exact_diameter(&subsample)
}

fn exact_diameter(points: &[Vector3<f64>]) -> f64 {
    let squared = (0..points.len())
        .into_par_iter()
        .map(|i| {
            let p = points[i];
            points[i + 1..]
                .iter()
                .map(|q| (p - q).norm_squared())
                .fold(0.0, f64::max)
        })
        .reduce(|| 0.0, f64::max);
    squared.sqrt()
}

/// `models_info.json`'s entry, as in the file (millimetres).
#[derive(Serialize)]
struct ModelInfoEntry {
    diameter: f64,
    min_x: f64,
    min_y: f64,
    min_z: f64,
    size_x: f64,
    size_y: f64,
    size_z: f64,
    #[serde(skip_serializing_if = "Vec::is_empty")]
    symmetries_discrete: Vec<[f64; 16]>,
    #[serde(skip_serializing_if = "Vec::is_empty")]
    symmetries_continuous: Vec<ContinuousSymmetryEntry>,
    glint_symmetry: String,
    glint_symmetry_tolerance_mm: f64,
}

#[derive(Serialize)]
struct ContinuousSymmetryEntry {
    axis: [f64; 3],
    /// mm
    offset: [f64; 3],
}

/// Writes each `(obj_id, mesh in metres, symmetry)` as `models_dir/obj_XXXXXX.ply` (binary
/// PLY in millimetres) and all of them into `models_dir/models_info.json` (diameter from
/// [`mesh_diameter_m`], bounding box, BOP's symmetry lists and Glint's exact group). Creates
/// `models_dir`. Returns the infos, in the order given.
pub fn write_models(
    models_dir: &Path,
    models: &[(u32, &TriMesh, &Symmetry)],
) -> Result<Vec<ModelInfo>, DatasetError> {
    create_directory(models_dir)?;
    let info_path = models_dir.join("models_info.json");
    let mut entries = BTreeMap::new();
    let mut infos = Vec::with_capacity(models.len());
    for &(obj_id, mesh, symmetry) in models {
        let path = model_path(models_dir, obj_id);
        let Some((min, max)) = mesh.aabb() else {
            return Err(DatasetError::Invalid {
                path,
                problem: "the mesh has no vertices".to_owned(),
            });
        };
        if entries.contains_key(&obj_id) {
            return Err(DatasetError::Invalid {
                path: info_path,
                problem: format!("object id {obj_id} is given twice"),
            });
        }
        write_ply(
            &path,
            mesh,
            LengthUnit::Millimetre,
            PlyEncoding::BinaryLittleEndian,
        )?;
        let bbox = ModelBox {
            min_m: min.coords.cast(),
            size_m: (max - min).cast(),
        };
        let info = ModelInfo {
            diameter_m: mesh_diameter_m(mesh),
            bbox: Some(bbox),
            symmetry: ModelSymmetry::from_glint(symmetry),
        };
        entries.insert(obj_id, model_info_entry(&info, &bbox, symmetry));
        infos.push(info);
    }
    write_bop_style_object(&info_path, entries)?;
    Ok(infos)
}

/// The `models_info.json` entry of `info`, whose box is `bbox` (every written model has one).
fn model_info_entry(info: &ModelInfo, bbox: &ModelBox, symmetry: &Symmetry) -> ModelInfoEntry {
    let (min, size) = (bbox.min_m * MM_PER_M, bbox.size_m * MM_PER_M);
    ModelInfoEntry {
        diameter: info.diameter_m * MM_PER_M,
        min_x: min.x,
        min_y: min.y,
        min_z: min.z,
        size_x: size.x,
        size_y: size.y,
        size_z: size.z,
        symmetries_discrete: info
            .symmetry
            .discrete
            .iter()
            .map(matrix4_mm_from_isometry)
            .collect(),
        symmetries_continuous: info
            .symmetry
            .continuous
            .iter()
            .map(|c| ContinuousSymmetryEntry {
                axis: [c.axis.x, c.axis.y, c.axis.z],
                offset: (c.offset_m * MM_PER_M).into(),
            })
            .collect(),
        glint_symmetry: symmetry.to_string(),
        glint_symmetry_tolerance_mm: symmetry.tolerance_m * MM_PER_M,
    }
}

/// Reads `models_info.json`: object id → info, in metres. Errors name the key.
pub fn read_models_info(path: &Path) -> Result<BTreeMap<u32, ModelInfo>, DatasetError> {
    let value = read_json_file(path)?;
    let root = JsonNode::root(path, &value);
    let mut infos = BTreeMap::new();
    for (key, entry) in root.entries()? {
        let obj_id: u32 = key
            .parse()
            .map_err(|_| entry.error("an object id must be a whole number"))?;
        infos.insert(obj_id, parse_model_info(&entry)?);
    }
    Ok(infos)
}

fn parse_model_info(entry: &JsonNode<'_>) -> Result<ModelInfo, DatasetError> {
    let mm = |key: &str| entry.field(key)?.f64();
    let diameter_node = entry.field("diameter")?;
    let diameter_mm = diameter_node.f64()?;
    if diameter_mm <= 0.0 {
        return Err(diameter_node.error(format!("diameter {diameter_mm} mm must be positive")));
    }
    let bbox = if entry.optional_field("min_x").is_some() {
        Some(ModelBox {
            min_m: Vector3::new(mm("min_x")?, mm("min_y")?, mm("min_z")?) / MM_PER_M,
            size_m: Vector3::new(mm("size_x")?, mm("size_y")?, mm("size_z")?) / MM_PER_M,
        })
    } else {
        None
    };
    let mut discrete = Vec::new();
    if let Some(list) = entry.optional_field("symmetries_discrete") {
        for item in list.items()? {
            let m = item.f64_array_flattened::<16>()?;
            discrete.push(isometry_from_matrix4_mm(&m).map_err(|p| item.error(p))?);
        }
    }
    let mut continuous = Vec::new();
    if let Some(list) = entry.optional_field("symmetries_continuous") {
        for item in list.items()? {
            let axis_node = item.field("axis")?;
            let axis = Vector3::from(axis_node.f64_array::<3>()?);
            let axis = Unit::try_new(axis, 1e-9)
                .ok_or_else(|| axis_node.error("the axis must not be zero"))?;
            let offset_mm = match item.optional_field("offset") {
                Some(node) => Vector3::from(node.f64_array::<3>()?),
                None => Vector3::zeros(),
            };
            continuous.push(ContinuousSymmetry {
                axis,
                offset_m: offset_mm / MM_PER_M,
            });
        }
    }
    let glint = match entry.optional_field("glint_symmetry") {
        Some(node) => {
            let spec = node
                .value()
                .as_str()
                .ok_or_else(|| node.error("expected a symmetry spec string"))?;
            let symmetry: Symmetry = spec.parse().map_err(|p: String| node.error(p))?;
            let tolerance_mm = match entry.optional_field("glint_symmetry_tolerance_mm") {
                Some(node) => node.f64()?,
                None => 0.0,
            };
            Some(symmetry.with_tolerance(tolerance_mm / MM_PER_M))
        }
        None => None,
    };
    Ok(ModelInfo {
        diameter_m: diameter_mm / MM_PER_M,
        bbox,
        symmetry: ModelSymmetry {
            discrete,
            continuous,
            glint,
        },
    })
}
