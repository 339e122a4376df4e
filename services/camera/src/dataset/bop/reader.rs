//! Reading one BOP scene, Glint's or a real dataset's.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use glint_geometry::image::{DepthMap, Image};

use super::camera::{BopCamera, UnsizedCamera, read_dataset_camera};
use super::gt::{BopGt, BopGtInfo};
use super::{BopSceneLayout, MaskKind, image_file_name};
use crate::dataset::error::DatasetError;
use crate::dataset::image_files::{
    decode_image, depth_from_units, gray8_from, gray16_from, image_dimensions, pattern_from,
};
use crate::dataset::json::{JsonNode, read_json_file};
use crate::dataset::{PatternImage, StereoSide};

/// Extensions tried, in order, for an image file: PNG (BOP), TIFF (ITODD), JPEG (PBR
/// renderings), BMP.
const IMAGE_EXTENSIONS: [&str; 6] = ["png", "tif", "tiff", "jpg", "jpeg", "bmp"];

/// One BOP scene directory (`<split>/XXXXXX/`), its JSON files parsed and checked on
/// opening, its images read on demand.
///
/// `scene_camera.json` is required; `scene_gt.json`, `scene_gt_info.json`, the image
/// directories and Glint's `glint/` files are optional (test splits have no public GT, ITODD
/// has gray but no rgb, ...), and asking for what is missing is an error naming the file.
/// Extra keys (T-LESS's `elev`, `mode`, `view_level`) are ignored.
#[derive(Clone, Debug)]
pub struct BopSceneReader {
    layout: BopSceneLayout,
    cameras: BTreeMap<u32, UnsizedCamera>,
    gts: Option<BTreeMap<u32, Vec<BopGt>>>,
    gt_infos: Option<BTreeMap<u32, Vec<BopGtInfo>>>,
    image_size: Option<(u32, u32)>,
}

impl BopSceneReader {
    /// Opens a classic single-sensor scene (`scene_camera.json`, `depth/`, ...).
    pub fn open(scene_dir: impl Into<PathBuf>) -> Result<Self, DatasetError> {
        let layout = BopSceneLayout::new(scene_dir);
        let camera_json = layout.scene_camera_json();
        if !camera_json.exists() {
            let sensors = sensors_in(layout.scene_dir());
            if !sensors.is_empty() {
                return Err(DatasetError::Invalid {
                    path: camera_json,
                    problem: format!(
                        "missing; this is a multi-sensor scene with files for {}: open it with \
                         BopSceneReader::open_sensor",
                        sensors.join(", ")
                    ),
                });
            }
        }
        Self::from_layout(layout)
    }

    /// Opens one sensor of a multi-sensor scene (`scene_camera_<sensor>.json`,
    /// `gray_<sensor>/`, ...; XYZ-IBD's sensors are `xyz`, `photoneo` and `realsense`).
    pub fn open_sensor(scene_dir: impl Into<PathBuf>, sensor: &str) -> Result<Self, DatasetError> {
        Self::from_layout(BopSceneLayout::for_sensor(scene_dir, sensor))
    }

    /// Opens the scene `layout` describes.
    pub fn from_layout(layout: BopSceneLayout) -> Result<Self, DatasetError> {
        let cameras = read_per_image(&layout.scene_camera_json(), |node| {
            UnsizedCamera::parse(node)
        })?;
        let gts =
            read_optional_per_image(&layout.scene_gt_json(), |node| -> Result<Vec<BopGt>, _> {
                node.items()?.iter().map(BopGt::parse).collect()
            })?;
        let gt_infos = read_optional_per_image(
            &layout.scene_gt_info_json(),
            |node| -> Result<Vec<BopGtInfo>, _> {
                node.items()?.iter().map(BopGtInfo::parse).collect()
            },
        )?;
        if let (Some(gts), Some(infos)) = (&gts, &gt_infos) {
            for (im_id, image_infos) in infos {
                let gt_count = gts.get(im_id).map_or(0, Vec::len);
                if image_infos.len() != gt_count {
                    return Err(DatasetError::Field {
                        path: layout.scene_gt_info_json(),
                        key: format!("/{im_id}"),
                        problem: format!(
                            "{} entries, but scene_gt has {gt_count} instances for this image",
                            image_infos.len()
                        ),
                    });
                }
            }
        }
        Ok(Self {
            layout,
            cameras,
            gts,
            gt_infos,
            image_size: None,
        })
    }

    /// Uses `width × height` px for every image's intrinsics instead of reading it from the
    /// image files.
    pub fn with_image_size(mut self, width_px: u32, height_px: u32) -> Self {
        self.image_size = Some((width_px, height_px));
        self
    }

    /// Where the scene's files are.
    pub fn layout(&self) -> &BopSceneLayout {
        &self.layout
    }

    /// `<dataset>/models`, two levels above the scene, if the scene path has them.
    pub fn models_dir(&self) -> Option<PathBuf> {
        Some(self.dataset_root()?.join("models"))
    }

    fn dataset_root(&self) -> Option<&Path> {
        self.layout.scene_dir().parent()?.parent()
    }

    /// The image ids of `scene_camera.json`, ascending.
    pub fn image_ids(&self) -> Vec<u32> {
        self.cameras.keys().copied().collect()
    }

    /// Whether the scene has `scene_gt.json`.
    pub fn has_gt(&self) -> bool {
        self.gts.is_some()
    }

    /// Image `im_id`'s ground truth, GT index = position; `None` without `scene_gt.json` or
    /// without an entry for the image.
    pub fn gt(&self, im_id: u32) -> Option<&[BopGt]> {
        self.gts.as_ref()?.get(&im_id).map(Vec::as_slice)
    }

    /// Image `im_id`'s GT info, one per GT instance; `None` without `scene_gt_info.json` or
    /// an entry for the image.
    pub fn gt_info(&self, im_id: u32) -> Option<&[BopGtInfo]> {
        self.gt_infos.as_ref()?.get(&im_id).map(Vec::as_slice)
    }

    fn unsized_camera(&self, im_id: u32) -> Result<&UnsizedCamera, DatasetError> {
        self.cameras.get(&im_id).ok_or_else(|| DatasetError::Field {
            path: self.layout.scene_camera_json(),
            key: format!("/{im_id}"),
            problem: "no such image in this scene".to_owned(),
        })
    }

    /// Image `im_id`'s camera in Glint's conventions. The image size comes from
    /// [`with_image_size`](Self::with_image_size), else the depth or gray/rgb file's header,
    /// else the dataset's `camera.json`.
    pub fn camera(&self, im_id: u32) -> Result<BopCamera, DatasetError> {
        let camera = self.unsized_camera(im_id)?;
        let (width, height) = self.image_size(im_id)?;
        camera
            .with_size(width, height)
            .map_err(|problem| DatasetError::Field {
                path: self.layout.scene_camera_json(),
                key: format!("/{im_id}/cam_K"),
                problem: format!("unusable for a {width}×{height} px image: {problem}"),
            })
    }

    fn image_size(&self, im_id: u32) -> Result<(u32, u32), DatasetError> {
        if let Some(size) = self.image_size {
            return Ok(size);
        }
        let dirs = [
            self.layout.depth_dir(),
            self.layout.gray_dir(),
            self.layout.rgb_dir(),
        ];
        if let Some(path) = dirs.iter().find_map(|dir| find_image(dir, im_id)) {
            return image_dimensions(&path);
        }
        let camera_json = self
            .dataset_root()
            .map(|root| root.join(format!("camera{}.json", self.layout.suffix)));
        if let Some(path) = camera_json.filter(|path| path.is_file()) {
            let camera = read_dataset_camera(&path)?;
            return Ok((camera.intrinsics.width_px, camera.intrinsics.height_px));
        }
        Err(DatasetError::Field {
            path: self.layout.scene_camera_json(),
            key: format!("/{im_id}"),
            problem: "the image size is unknown: no depth, gray or rgb image and no camera.json; \
                      give it with BopSceneReader::with_image_size"
                .to_owned(),
        })
    }

    /// Image `im_id`'s depth in metres, NaN where the file has 0.
    pub fn depth(&self, im_id: u32) -> Result<DepthMap, DatasetError> {
        let camera = self.unsized_camera(im_id)?;
        let path = find_image(&self.layout.depth_dir(), im_id)
            .unwrap_or_else(|| self.layout.depth_png(im_id));
        let depth_scale_mm = camera.depth_scale_mm.ok_or_else(|| DatasetError::Field {
            path: self.layout.scene_camera_json(),
            key: format!("/{im_id}/depth_scale"),
            problem: format!("missing, so {} cannot be read in mm", path.display()),
        })?;
        let units = gray16_from(&path, decode_image(&path)?)?;
        Ok(depth_from_units(&units, depth_scale_mm))
    }

    /// Image `im_id` from `gray/`, or else from `rgb/` converted to luma (Rec. 709).
    pub fn gray(&self, im_id: u32) -> Result<Image<u8>, DatasetError> {
        let path = find_image(&self.layout.gray_dir(), im_id)
            .or_else(|| find_image(&self.layout.rgb_dir(), im_id))
            .unwrap_or_else(|| self.layout.gray_png(im_id));
        gray8_from(&path, decode_image(&path)?)
    }

    /// The mask of GT instance `gt_index` of image `im_id`, as stored (0 and 255).
    pub fn mask(
        &self,
        im_id: u32,
        gt_index: usize,
        kind: MaskKind,
    ) -> Result<Image<u8>, DatasetError> {
        let path = self.layout.mask_png(im_id, gt_index, kind);
        gray8_from(&path, decode_image(&path)?)
    }

    /// Glint's pattern image of `side` for image `im_id`, at its stored bit depth.
    pub fn pattern(&self, im_id: u32, side: StereoSide) -> Result<PatternImage, DatasetError> {
        let path = self.layout.pattern_png(im_id, side);
        pattern_from(&path, decode_image(&path)?)
    }

    /// Every shot of a view's pattern images, in projection order: shot 0 and then
    /// `XXXXXX_01.png`, ... as long as they exist (a single-shot capture gives one).
    pub fn pattern_shots(
        &self,
        im_id: u32,
        side: StereoSide,
    ) -> Result<Vec<PatternImage>, DatasetError> {
        let mut shots = vec![self.pattern(im_id, side)?];
        loop {
            let path = self.layout.pattern_shot_png(im_id, side, shots.len());
            if !path.is_file() {
                return Ok(shots);
            }
            shots.push(pattern_from(&path, decode_image(&path)?)?);
        }
    }

    /// Glint's `glint/gt_materials.json`, `None` if the scene has none.
    pub fn gt_materials(&self) -> Result<Option<serde_json::Value>, DatasetError> {
        let path = self.layout.gt_materials_json();
        if !path.exists() {
            return Ok(None);
        }
        read_json_file(&path).map(Some)
    }
}

/// `dir/XXXXXX.<ext>` for the first extension of [`IMAGE_EXTENSIONS`] that exists.
fn find_image(dir: &Path, im_id: u32) -> Option<PathBuf> {
    IMAGE_EXTENSIONS
        .iter()
        .map(|extension| dir.join(image_file_name(im_id, extension)))
        .find(|path| path.is_file())
}

/// The sensors of a multi-sensor scene: `<s>` of every `scene_camera_<s>.json`.
fn sensors_in(scene_dir: &Path) -> Vec<String> {
    let Ok(entries) = std::fs::read_dir(scene_dir) else {
        return Vec::new();
    };
    let mut sensors: Vec<String> = entries
        .filter_map(|entry| {
            let name = entry.ok()?.file_name().into_string().ok()?;
            Some(
                name.strip_prefix("scene_camera_")?
                    .strip_suffix(".json")?
                    .to_owned(),
            )
        })
        .collect();
    sensors.sort();
    sensors
}

/// Reads a JSON object keyed by image id, parsing each entry with `parse`.
fn read_per_image<T>(
    path: &Path,
    parse: impl Fn(&JsonNode<'_>) -> Result<T, DatasetError>,
) -> Result<BTreeMap<u32, T>, DatasetError> {
    let value = read_json_file(path)?;
    let root = JsonNode::root(path, &value);
    let mut out = BTreeMap::new();
    for (key, entry) in root.entries()? {
        let im_id: u32 = key
            .parse()
            .map_err(|_| entry.error("an image id must be a whole number"))?;
        if out.insert(im_id, parse(&entry)?).is_some() {
            return Err(entry.error(format!("image {im_id} appears twice")));
        }
    }
    Ok(out)
}

/// [`read_per_image`] for a file that may be missing (`None` then).
fn read_optional_per_image<T>(
    path: &Path,
    parse: impl Fn(&JsonNode<'_>) -> Result<T, DatasetError>,
) -> Result<Option<BTreeMap<u32, T>>, DatasetError> {
    if !path.exists() {
        return Ok(None);
    }
    read_per_image(path, parse).map(Some)
}
