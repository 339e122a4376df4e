//! How much of each instance a camera sees: its amodal mask (the whole silhouette, the
//! instance rendered alone) against its visible mask (where it is the first surface in the
//! full scene), as BOP's `scene_gt_info.json` states them (`px_count_all`, `px_count_visib`,
//! `visib_fract`).
//!
//! Both masks are primary-ray label passes through pixel centres, no shading: the same rays
//! that give a [`crate::capture::CaptureTruth`]'s `label`, so the visible mask equals
//! `truth.label == label`. Ground truth, for evaluation and for selecting which instances to
//! evaluate on.

use glint_geometry::image::{Image, PixelRect};
use glint_render::integrator::{Camera, render_labels};
use glint_render::scene::Scene;
use nalgebra::Point3;

/// One instance's masks and pixel counts in one camera.
#[derive(Clone, Debug, PartialEq)]
pub struct InstanceVisibility {
    /// The instance's label.
    pub label: u16,
    /// The whole silhouette, occluders ignored: 255 in, 0 out (BOP's `mask/`).
    pub mask_all: Image<u8>,
    /// The part of it that is the first surface in the full scene (BOP's `mask_visib/`).
    pub mask_visib: Image<u8>,
    /// Pixels of `mask_all`.
    pub px_count_all: u64,
    /// Pixels of `mask_visib`.
    pub px_count_visib: u64,
    /// `px_count_visib / px_count_all`, 0 when the silhouette misses the image.
    pub visib_fract: f64,
}

/// The visibility in `camera` of each instance of `scene` labelled with one of `labels` (in
/// that order; a label no instance has gets empty masks). One label pass of the full scene,
/// then one per instance restricted to the image box of its world bounds.
pub fn instance_visibility(
    scene: &Scene,
    camera: &Camera,
    labels: &[u16],
) -> Vec<InstanceVisibility> {
    let visible_labels = render_labels(scene, camera, None, None);
    labels
        .iter()
        .map(|&label| {
            let instance = scene.instances().iter().position(|i| i.label == label);
            let amodal = match instance {
                Some(i) => {
                    let roi = projected_bounds(scene, camera, i as u32);
                    render_labels(scene, camera, roi, Some(i as u32))
                }
                None => Image::filled_like(&visible_labels, 0u16),
            };
            let to_mask = |img: &Image<u16>| img.map(|l| if l == label { 255u8 } else { 0 });
            let (mask_all, mask_visib) = (to_mask(&amodal), to_mask(&visible_labels));
            let count = |m: &Image<u8>| m.data().iter().filter(|&&x| x != 0).count() as u64;
            let (px_count_all, px_count_visib) = (count(&mask_all), count(&mask_visib));
            InstanceVisibility {
                label,
                mask_all,
                mask_visib,
                px_count_all,
                px_count_visib,
                visib_fract: if px_count_all > 0 {
                    px_count_visib as f64 / px_count_all as f64
                } else {
                    0.0
                },
            }
        })
        .collect()
}

/// The pixel box covering instance `instance`'s world bounds in `camera`, one pixel of margin;
/// `None` (the full image) when a corner of the bounds is not in front of the camera.
fn projected_bounds(scene: &Scene, camera: &Camera, instance: u32) -> Option<PixelRect> {
    let (lo, hi) = scene.instance_bounds(instance)?;
    let t_c_w = camera.t_w_c.inverse();
    let (mut u0, mut v0, mut u1, mut v1) = (f64::MAX, f64::MAX, f64::MIN, f64::MIN);
    for corner in 0..8 {
        let pick = |bit: usize, a: f32, b: f32| if corner & bit == 0 { a } else { b };
        let p_w = Point3::new(
            pick(1, lo.x, hi.x),
            pick(2, lo.y, hi.y),
            pick(4, lo.z, hi.z),
        );
        let p_c = t_c_w * p_w.cast::<f64>();
        let uv = camera.intrinsics.project(&p_c)?;
        (u0, v0, u1, v1) = (u0.min(uv.x), v0.min(uv.y), u1.max(uv.x), v1.max(uv.y));
    }
    let (w, h) = (
        camera.intrinsics.width_px as f64,
        camera.intrinsics.height_px as f64,
    );
    let u_min = (u0.floor() - 1.0).clamp(0.0, w) as u32;
    let v_min = (v0.floor() - 1.0).clamp(0.0, h) as u32;
    let u_max = (u1.ceil() + 1.0).clamp(0.0, w) as u32;
    let v_max = (v1.ceil() + 1.0).clamp(0.0, h) as u32;
    Some(PixelRect {
        u_min,
        v_min,
        width: u_max - u_min,
        height: v_max - v_min,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::materials;
    use glint_geometry::TriMesh;
    use glint_geometry::camera::PinholeIntrinsics;
    use glint_render::scene::SceneInstance;
    use nalgebra::{Isometry3, Vector3};

    /// Two 40 × 40 mm squares seen straight down from 0.5 m: the lower one at z = 0, the
    /// upper one 10 mm above it shifted 20 mm along x, covering the lower one's right half.
    #[test]
    fn half_occluded_square_has_visib_fract_from_geometry() {
        let square = TriMesh::cuboid([0.0, 0.0, 0.0], [0.02, 0.02, 0.001]);
        let instance = |label: u16, x: f64, z: f64| SceneInstance {
            mesh: 0,
            t_w_o: Isometry3::translation(x, 0.0, z),
            material: 0,
            label,
        };
        let scene = Scene::build(
            &[square],
            vec![instance(1, 0.0, 0.0), instance(2, 0.02, 0.01)],
            vec![materials::diffuse_twin()],
        )
        .unwrap();
        let intrinsics = PinholeIntrinsics::new(320, 256, 800.0, 800.0, 160.0, 128.0).unwrap();
        let camera = Camera {
            intrinsics,
            t_w_c: Isometry3::face_towards(
                &Point3::new(0.0, 0.0, 0.5),
                &Point3::origin(),
                &Vector3::y(),
            ),
        };
        let vis = instance_visibility(&scene, &camera, &[1, 2, 7]);
        // Lower square's top face at z = 1 mm, 499 mm away: 40 mm · 800 px / 0.499 m ≈ 64 px a
        // side. The upper square spans x ∈ [0, 40] mm; its left edge x = 0 projects to the
        // principal point's column at any depth, so it hides exactly the lower's x > 0 half.
        let side_px = |z_m: f64| 0.04 * 800.0 / z_m;
        let all_expected = side_px(0.499).powi(2);
        let lower = &vis[0];
        let tolerance = 4.0 * side_px(0.499); // a pixel row and column of rounding on each edge
        assert!(
            (lower.px_count_all as f64 - all_expected).abs() < tolerance,
            "{} vs {all_expected}",
            lower.px_count_all
        );
        // Visible: the left half (x < 0) of the lower square.
        assert!(
            (lower.visib_fract - 0.5).abs() < 2.0 / side_px(0.499),
            "{}",
            lower.visib_fract
        );
        let upper = &vis[1];
        assert_eq!(upper.px_count_visib, upper.px_count_all);
        assert_eq!(upper.visib_fract, 1.0);
        assert!((upper.px_count_all as f64 - side_px(0.489).powi(2)).abs() < 4.0 * side_px(0.489));
        // Visible ⊆ amodal, pixel by pixel.
        for v in &vis[..2] {
            assert!(
                v.mask_visib
                    .data()
                    .iter()
                    .zip(v.mask_all.data())
                    .all(|(&a, &b)| a == 0 || b == 255)
            );
        }
        assert_eq!((vis[2].px_count_all, vis[2].visib_fract), (0, 0.0));
        // The box-restricted amodal pass loses nothing against a full-image pass, and the
        // visible mask is the shading render's label image.
        let full = render_labels(&scene, &camera, None, Some(0));
        let full_mask: Vec<u8> = full
            .data()
            .iter()
            .map(|&l| if l == 1 { 255 } else { 0 })
            .collect();
        assert_eq!(lower.mask_all.data(), &full_mask[..]);
        let projector = glint_render::rig::SliRig::ensenso_n35()
            .projector(&camera.t_w_c, glint_render::projector::Pattern::White);
        let shaded = glint_render::integrator::render(
            &scene,
            &camera,
            &projector,
            &glint_render::integrator::RenderSettings {
                transport: glint_render::integrator::LightTransport::SinglePath,
                samples_per_pixel: 1,
                roi: None,
                seed: 1,
            },
        );
        let shaded_mask: Vec<u8> = shaded
            .label
            .data()
            .iter()
            .map(|&l| if l == 1 { 255 } else { 0 })
            .collect();
        assert_eq!(lower.mask_visib.data(), &shaded_mask[..]);
    }
}
