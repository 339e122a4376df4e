//! A mock capture recorded as a BOP image: the camera, depth, both pattern images (8-bit) and
//! the annotations (GT poses, amodal and visible masks, GT info) — what `glint capture` and the
//! experiments' scene caches write.

use glint_geometry::image::{DepthMap, Image};
use nalgebra::Isometry3;

use crate::capture::{MockSliCamera, StereoCapture};
use crate::dataset::bop::{BopGt, BopGtInfo, BopSceneWriter, GtInfoError, MaskKind};
use crate::dataset::{DatasetError, PatternImage, StereoSide};
use crate::visibility::{InstanceVisibility, instance_visibility};

/// Why a capture could not be recorded.
#[derive(Debug, thiserror::Error)]
pub enum RecordError {
    /// A BOP file could not be written; the error names it.
    #[error(transparent)]
    Dataset(#[from] DatasetError),
    /// The GT info of an instance could not be computed: the depth map's size differs from
    /// the camera's image size.
    #[error("GT info of image {im_id}: {source}")]
    GtInfo {
        /// The image being written.
        im_id: u32,
        /// Why the GT info failed.
        #[source]
        source: GtInfoError,
    },
}

/// Digital numbers (full scale `max_dn`) as 8-bit values, rounded down.
pub fn to_8bit(img: &Image<u16>, max_dn: u16) -> Image<u8> {
    img.map(|d| (d as u32 * 255 / max_dn.max(1) as u32) as u8)
}

/// One view as a BOP image: camera, depth, left/right patterns of every shot (8-bit), and the
/// annotations of [`write_bop_annotations`] for the parts at `poses` (scene labels 1..=N), all
/// as `obj_id`.
pub fn write_bop_image(
    bop: &mut BopSceneWriter,
    im_id: u32,
    capture: &StereoCapture,
    camera: &MockSliCamera<'_>,
    poses: &[Isometry3<f64>],
    obj_id: u32,
) -> Result<(), RecordError> {
    bop.write_depth(im_id, &capture.depth)?;
    let max_dn = camera.config.sensor.max_dn();
    for (index, side) in [StereoSide::Left, StereoSide::Right]
        .into_iter()
        .enumerate()
    {
        for (shot, image) in capture.shot_images(index).into_iter().enumerate() {
            let pattern = PatternImage::Bits8(to_8bit(image, max_dn));
            bop.write_pattern_shot(im_id, side, shot, &pattern)?;
        }
    }
    write_bop_annotations(
        bop,
        im_id,
        &capture.t_w_c,
        camera,
        poses,
        obj_id,
        Some(&capture.depth),
    )?;
    Ok(())
}

/// A view's camera (intrinsics, world → camera) and, for every instance whose silhouette
/// reaches the left image, its GT pose, amodal `mask/`, `mask_visib/` and GT info
/// (`px_count_valid` from `depth` when given). Returns the instances written, GT index order.
pub fn write_bop_annotations(
    bop: &mut BopSceneWriter,
    im_id: u32,
    t_w_c: &Isometry3<f64>,
    camera: &MockSliCamera<'_>,
    poses: &[Isometry3<f64>],
    obj_id: u32,
    depth: Option<&DepthMap>,
) -> Result<Vec<InstanceVisibility>, RecordError> {
    let t_c_w = t_w_c.inverse();
    bop.set_camera(im_id, &camera.rig.stereo.intrinsics, Some(&t_c_w))?;
    let [left, _] = camera.rig.cameras(t_w_c);
    let labels: Vec<u16> = (1..=poses.len() as u16).collect();
    let seen: Vec<InstanceVisibility> = instance_visibility(camera.scene, &left, &labels)
        .into_iter()
        .filter(|v| v.px_count_all > 0)
        .collect();
    let mut gts = Vec::with_capacity(seen.len());
    let mut infos = Vec::with_capacity(seen.len());
    for (gt_index, v) in seen.iter().enumerate() {
        bop.write_mask(im_id, gt_index, MaskKind::Full, &v.mask_all)?;
        bop.write_mask(im_id, gt_index, MaskKind::Visible, &v.mask_visib)?;
        gts.push(BopGt {
            obj_id,
            t_c_o: t_c_w * poses[v.label as usize - 1],
        });
        infos.push(
            BopGtInfo::from_masks(&v.mask_all, &v.mask_visib, depth)
                .map_err(|source| RecordError::GtInfo { im_id, source })?,
        );
    }
    bop.set_gt(im_id, &gts);
    bop.set_gt_info(im_id, &infos);
    Ok(seen)
}
