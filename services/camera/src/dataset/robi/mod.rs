//! ROBI's own layout (Yang et al., "ROBI: A Multi-View Dataset for Reflective Objects in
//! Robotic Bin-Picking", IROS 2021), read-only.
//!
//! The dataset itself is not reachable from here; this follows its public toolkit,
//! github.com/junyang224/ROBI_Toolkit (`ROBI_Dataset_Structure.txt`, `read_scene_imgs.py`,
//! `read_pattern_imgs.py`, `read_synthetic_imgs.py`, `inout.py`, `cam/*.yml`):
//!
//! ```text
//! <root>/<Object>/Scene_<n>/
//!     GT_world2obj.json                 {"Object_1": 4×4, "Object_2": 4×4, ...}
//!     <Sensor>/                         Ensenso or RealSense
//!         list.txt                      view names, one a line: view_0, view_1, ...
//!         Depth/DEPTH_<view>.png        16-bit, depth_mm = value × depth_unit, 0 = none
//!         Depth/DEPTH_<view>.json       {"cam_pose": 4×4}
//!         StereoPattern/LEFT_<view>.bmp, RIGHT_<view>.bmp (+ .json with "cam_pose")
//!         Stereo/LEFT_<view>.bmp, ...   (Ensenso: the same views without the pattern)
//! <toolkit>/cam/<Sensor>_DEPTH.yml      depth_unit, width, height, fx, fy, cx, cy
//! ```
//!
//! What the toolkit shows and what is assumed:
//! - 4×4 matrices are read with numpy's `reshape(4, 4)`, so a flat list of 16 is row-major;
//!   nested rows are accepted too.
//! - `GT_world2obj.json` holds object → world poses (`t_w_o`): the toolkit calls them "pose
//!   of objects in world coordinate", and its synthetic reader computes
//!   `T_cam2obj = inv(T_world2cam) · T_world2obj`, i.e. object → camera from camera → world
//!   and object → world. Keys are `Object_<i>` (`eval_baselines.py`).
//! - `cam_pose` is camera → world (`t_w_c`, "the pose of camera in world frame").
//! - Lengths in the matrices are millimetres (an assumption: the toolkit never scales them,
//!   and its depth units are millimetres).
//! - Ensenso depth units are 0.03125 mm (`cam/Ensenso_DEPTH.yml`).
//! - The `.yml` intrinsics follow OpenCV's pixel convention (centres at integers), so
//!   Glint's principal point is theirs + 0.5 (an assumption, as for every OpenCV
//!   calibration).
//! - Models are STL in millimetres; their location is not part of the scene layout, so
//!   [`read_robi_model`] takes a path.

#[cfg(test)]
mod tests;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use glint_geometry::LengthUnit;
use glint_geometry::camera::PinholeIntrinsics;
use glint_geometry::image::{DepthMap, Image};
use glint_geometry::io::{LoadedMesh, read_mesh};
use nalgebra::Isometry3;

use super::StereoSide;
use super::error::{DatasetError, read_file};
use super::image_files::{decode_image, depth_from_units, gray8_from, gray16_from};
use super::json::{JsonNode, read_json_file};
use super::transforms::isometry_from_matrix4_mm;

/// Offset from an OpenCV principal point to Glint's (pixel centres at +0.5).
const GLINT_MINUS_OPENCV_PX: f64 = 0.5;

/// The two sensors of ROBI, and their directory names.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum RobiSensor {
    /// The Ensenso N35 structured-light stereo camera (`Ensenso/`).
    Ensenso,
    /// The Intel RealSense depth camera (`RealSense/`).
    RealSense,
}

impl RobiSensor {
    /// `"Ensenso"` or `"RealSense"`.
    pub fn dir_name(self) -> &'static str {
        match self {
            Self::Ensenso => "Ensenso",
            Self::RealSense => "RealSense",
        }
    }
}

/// A depth camera of ROBI: intrinsics (Glint's pixel convention) and depth unit.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RobiDepthCamera {
    /// The depth image's pinhole intrinsics, px, Glint's pixel convention (OpenCV's + 0.5).
    pub intrinsics: PinholeIntrinsics,
    /// Millimetres per unit of the 16-bit depth files.
    pub depth_unit_mm: f64,
}

impl RobiDepthCamera {
    /// The Ensenso N35's depth camera as the toolkit's `cam/Ensenso_DEPTH.yml` gives it:
    /// 1280×1024 px, fx = fy = 1083.097046 px, (cx, cy) = (379.326874, 509.437195) px in
    /// OpenCV's convention, depth unit 0.03125 mm.
    pub fn ensenso() -> Self {
        Self {
            intrinsics: PinholeIntrinsics {
                width_px: 1280,
                height_px: 1024,
                fx_px: 1083.097046,
                fy_px: 1083.097046,
                cx_px: 379.326874 + GLINT_MINUS_OPENCV_PX,
                cy_px: 509.437195 + GLINT_MINUS_OPENCV_PX,
            },
            depth_unit_mm: 0.03125,
        }
    }

    /// Reads one of the toolkit's flat `key: value` camera files (`cam/Ensenso_DEPTH.yml`):
    /// `width`, `height`, `fx`, `fy`, `cx`, `cy` and `depth_unit` (or `depth_scale`, as the
    /// `_LEFT` files call it); other keys are ignored.
    pub fn read_yml(path: &Path) -> Result<Self, DatasetError> {
        let bytes = read_file(path)?;
        let text = String::from_utf8_lossy(&bytes);
        let mut values: BTreeMap<String, (usize, String)> = BTreeMap::new();
        for (index, raw) in text.lines().enumerate() {
            let line = raw.split('#').next().unwrap_or("").trim();
            if line.is_empty() || line.starts_with('%') || line.starts_with("---") {
                continue;
            }
            let Some((key, value)) = line.split_once(':') else {
                return Err(DatasetError::Line {
                    path: path.to_owned(),
                    line: index + 1,
                    problem: format!("expected `key: value`, found {line:?}"),
                });
            };
            values.insert(key.trim().to_owned(), (index + 1, value.trim().to_owned()));
        }
        let number = |keys: &[&str]| -> Result<f64, DatasetError> {
            let Some((line, text)) = keys.iter().find_map(|key| values.get(*key)) else {
                return Err(DatasetError::Field {
                    path: path.to_owned(),
                    key: keys[0].to_owned(),
                    problem: "missing".to_owned(),
                });
            };
            text.parse::<f64>()
                .ok()
                .filter(|x| x.is_finite())
                .ok_or_else(|| DatasetError::Line {
                    path: path.to_owned(),
                    line: *line,
                    problem: format!("{}: expected a number, found {text:?}", keys[0]),
                })
        };
        let size = |key: &str| -> Result<u32, DatasetError> {
            let value = number(&[key])?;
            if value.fract() != 0.0 || !(1.0..=65535.0).contains(&value) {
                return Err(DatasetError::Field {
                    path: path.to_owned(),
                    key: key.to_owned(),
                    problem: format!("{value} is not an image size in pixels"),
                });
            }
            Ok(value as u32)
        };
        let intrinsics = PinholeIntrinsics::new(
            size("width")?,
            size("height")?,
            number(&["fx"])?,
            number(&["fy"])?,
            number(&["cx"])? + GLINT_MINUS_OPENCV_PX,
            number(&["cy"])? + GLINT_MINUS_OPENCV_PX,
        )
        .map_err(|error| DatasetError::Invalid {
            path: path.to_owned(),
            problem: format!("unusable intrinsics: {error}"),
        })?;
        let depth_unit_mm = number(&["depth_unit", "depth_scale"])?;
        if depth_unit_mm <= 0.0 {
            return Err(DatasetError::Field {
                path: path.to_owned(),
                key: "depth_unit".to_owned(),
                problem: format!("{depth_unit_mm} mm must be positive"),
            });
        }
        Ok(Self {
            intrinsics,
            depth_unit_mm,
        })
    }
}

/// One object instance of a ROBI scene.
#[derive(Clone, Debug, PartialEq)]
pub struct RobiObjectPose {
    /// Its key in `GT_world2obj.json`, e.g. `Object_3`.
    pub name: String,
    /// Object → world, metres: `p_w = t_w_o · p_o`.
    pub t_w_o: Isometry3<f64>,
}

/// One object instance seen from one view.
#[derive(Clone, Debug, PartialEq)]
pub struct RobiViewGt {
    /// Its key in `GT_world2obj.json`, e.g. `Object_3`.
    pub name: String,
    /// Object → depth camera, metres: `t_c_o = t_w_c⁻¹ · t_w_o`.
    pub t_c_o: Isometry3<f64>,
}

/// One scene of one sensor in ROBI's layout (`<root>/<Object>/Scene_<n>/`).
#[derive(Clone, Debug)]
pub struct RobiSceneReader {
    scene_dir: PathBuf,
    sensor: RobiSensor,
    camera: RobiDepthCamera,
    objects: Vec<RobiObjectPose>,
    views: Vec<String>,
}

impl RobiSceneReader {
    /// Opens `scene_dir` for `sensor`, whose depth camera is `camera`: reads the object
    /// poses and the view list (`list.txt`, or else the `Depth/DEPTH_*.png` files).
    pub fn open(
        scene_dir: impl Into<PathBuf>,
        sensor: RobiSensor,
        camera: RobiDepthCamera,
    ) -> Result<Self, DatasetError> {
        let scene_dir = scene_dir.into();
        let objects = read_object_poses(&scene_dir.join("GT_world2obj.json"))?;
        let sensor_dir = scene_dir.join(sensor.dir_name());
        let list = sensor_dir.join("list.txt");
        let views = if list.exists() {
            read_view_list(&list)?
        } else {
            views_from_depth_files(&sensor_dir.join("Depth"))?
        };
        Ok(Self {
            scene_dir,
            sensor,
            camera,
            objects,
            views,
        })
    }

    /// The scene directory, `<root>/<Object>/Scene_<n>/`.
    pub fn scene_dir(&self) -> &Path {
        &self.scene_dir
    }

    /// The sensor's depth camera, as given to [`Self::open`].
    pub fn camera(&self) -> &RobiDepthCamera {
        &self.camera
    }

    /// The scene's object instances, in natural order of their names.
    pub fn objects(&self) -> &[RobiObjectPose] {
        &self.objects
    }

    /// The views, in `list.txt`'s order (or natural order of the depth files).
    pub fn views(&self) -> &[String] {
        &self.views
    }

    fn sensor_dir(&self) -> PathBuf {
        self.scene_dir.join(self.sensor.dir_name())
    }

    /// `<Sensor>/Depth/DEPTH_<view>.png`.
    pub fn depth_png(&self, view: &str) -> PathBuf {
        self.sensor_dir()
            .join("Depth")
            .join(format!("DEPTH_{view}.png"))
    }

    /// `<Sensor>/StereoPattern/LEFT_<view>.bmp` or `RIGHT_...`.
    pub fn pattern_bmp(&self, view: &str, side: StereoSide) -> PathBuf {
        self.sensor_dir()
            .join("StereoPattern")
            .join(format!("{}_{view}.bmp", side_prefix(side)))
    }

    /// The depth camera's pose for `view`: camera → world, metres.
    pub fn depth_t_w_c(&self, view: &str) -> Result<Isometry3<f64>, DatasetError> {
        read_cam_pose(&self.depth_png(view).with_extension("json"))
    }

    /// The pattern camera's pose for `view`: camera → world, metres.
    pub fn pattern_t_w_c(
        &self,
        view: &str,
        side: StereoSide,
    ) -> Result<Isometry3<f64>, DatasetError> {
        read_cam_pose(&self.pattern_bmp(view, side).with_extension("json"))
    }

    /// `view`'s depth in metres (NaN where the file has 0), checked against the camera's
    /// image size.
    pub fn depth(&self, view: &str) -> Result<DepthMap, DatasetError> {
        let path = self.depth_png(view);
        let units = gray16_from(&path, decode_image(&path)?)?;
        let k = &self.camera.intrinsics;
        if (units.width(), units.height()) != (k.width_px, k.height_px) {
            return Err(DatasetError::ImageContent {
                path,
                problem: format!(
                    "{}×{} px, but the depth camera is {}×{} px",
                    units.width(),
                    units.height(),
                    k.width_px,
                    k.height_px
                ),
            });
        }
        Ok(depth_from_units(&units, self.camera.depth_unit_mm))
    }

    /// `view`'s pattern image of `side`, 8-bit (colour BMPs are converted to luma).
    pub fn pattern(&self, view: &str, side: StereoSide) -> Result<Image<u8>, DatasetError> {
        let path = self.pattern_bmp(view, side);
        gray8_from(&path, decode_image(&path)?)
    }

    /// Every object's pose in `view`'s depth camera.
    pub fn gt_in_depth_camera(&self, view: &str) -> Result<Vec<RobiViewGt>, DatasetError> {
        let t_c_w = self.depth_t_w_c(view)?.inverse();
        Ok(self
            .objects
            .iter()
            .map(|object| RobiViewGt {
                name: object.name.clone(),
                t_c_o: t_c_w * object.t_w_o,
            })
            .collect())
    }
}

/// Reads a ROBI model: STL (or any mesh format Glint reads) in millimetres, returned in
/// metres.
pub fn read_robi_model(path: &Path) -> Result<LoadedMesh, DatasetError> {
    Ok(read_mesh(path, LengthUnit::Millimetre)?)
}

fn side_prefix(side: StereoSide) -> &'static str {
    match side {
        StereoSide::Left => "LEFT",
        StereoSide::Right => "RIGHT",
    }
}

/// `GT_world2obj.json`: name → object → world matrix (mm).
fn read_object_poses(path: &Path) -> Result<Vec<RobiObjectPose>, DatasetError> {
    let value = read_json_file(path)?;
    let root = JsonNode::root(path, &value);
    let mut objects = Vec::new();
    for (name, node) in root.entries()? {
        let m = node.f64_array_flattened::<16>()?;
        let t_w_o = isometry_from_matrix4_mm(&m).map_err(|p| node.error(p))?;
        objects.push(RobiObjectPose {
            name: name.to_owned(),
            t_w_o,
        });
    }
    objects.sort_by(|a, b| natural_key(&a.name).cmp(&natural_key(&b.name)));
    Ok(objects)
}

/// A view's `cam_pose` (camera → world, mm) in metres.
fn read_cam_pose(path: &Path) -> Result<Isometry3<f64>, DatasetError> {
    let value = read_json_file(path)?;
    let node = JsonNode::root(path, &value).field("cam_pose")?;
    let m = node.f64_array_flattened::<16>()?;
    isometry_from_matrix4_mm(&m).map_err(|p| node.error(p))
}

/// `list.txt`: one view name a line; blank lines skipped.
fn read_view_list(path: &Path) -> Result<Vec<String>, DatasetError> {
    let bytes = read_file(path)?;
    let text = String::from_utf8_lossy(&bytes);
    let mut views = Vec::new();
    for (index, line) in text.lines().enumerate() {
        let name = line.trim();
        if name.is_empty() {
            continue;
        }
        if name.contains(['/', '\\']) || name == "." || name == ".." {
            return Err(DatasetError::Line {
                path: path.to_owned(),
                line: index + 1,
                problem: format!("{name:?} is not a view name"),
            });
        }
        views.push(name.to_owned());
    }
    Ok(views)
}

/// The views of `Depth/DEPTH_<view>.png` files, in natural order.
fn views_from_depth_files(depth_dir: &Path) -> Result<Vec<String>, DatasetError> {
    let entries = std::fs::read_dir(depth_dir).map_err(|source| DatasetError::Read {
        path: depth_dir.to_owned(),
        source,
    })?;
    let mut views: Vec<String> = entries
        .filter_map(|entry| {
            let name = entry.ok()?.file_name().into_string().ok()?;
            Some(
                name.strip_prefix("DEPTH_")?
                    .strip_suffix(".png")?
                    .to_owned(),
            )
        })
        .collect();
    views.sort_by(|a, b| natural_key(a).cmp(&natural_key(b)));
    Ok(views)
}

/// Sorts `view_2` before `view_10`: the text before the trailing digits, then their value.
fn natural_key(name: &str) -> (&str, u64, &str) {
    let stem = name.trim_end_matches(|c: char| c.is_ascii_digit());
    let number = name[stem.len()..].parse().unwrap_or(0);
    (stem, number, name)
}
