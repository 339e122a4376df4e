//! A mesh's silhouette in a pinhole camera, and square dilation of masks: the part's pixels a
//! real system knows without a segmentation network — where the current pose hypothesis
//! projects, grown by the hypothesis' uncertainty.

use nalgebra::{Isometry3, Point2};

use crate::camera::PinholeIntrinsics;
use crate::image::{Image, SummedAreaTable};
use crate::mesh::TriMesh;

/// The amodal silhouette of `mesh` (metres, object frame) seen by a camera with `intrinsics`
/// at `t_c_o` (object → camera): `true` for every pixel whose centre lies inside a triangle's
/// projection. Occlusion by other objects is ignored; triangles with a vertex at or behind the
/// camera's plane `z ≤ near_m` are skipped (a part that close is not a view to take).
pub fn silhouette_mask(
    mesh: &TriMesh,
    intrinsics: &PinholeIntrinsics,
    t_c_o: &Isometry3<f64>,
) -> Image<bool> {
    const NEAR_M: f64 = 1e-3;
    let (w, h) = (intrinsics.width_px, intrinsics.height_px);
    let mut mask = vec![false; w as usize * h as usize];
    let projected: Vec<Option<Point2<f64>>> = mesh
        .vertices
        .iter()
        .map(|v| {
            let p_c = t_c_o * v.cast::<f64>();
            (p_c.z > NEAR_M).then(|| intrinsics.project(&p_c)).flatten()
        })
        .collect();
    for tri in &mesh.triangles {
        let [Some(a), Some(b), Some(c)] = tri.map(|i| projected.get(i as usize).copied().flatten())
        else {
            continue;
        };
        fill_triangle(&mut mask, w, h, a, b, c);
    }
    Image::from_parts(w, h, mask)
}

/// Sets every pixel whose centre lies inside (or on an edge of) the triangle `a b c`.
fn fill_triangle(
    mask: &mut [bool],
    w: u32,
    h: u32,
    a: Point2<f64>,
    b: Point2<f64>,
    c: Point2<f64>,
) {
    let edge = |p: Point2<f64>, q: Point2<f64>, x: f64, y: f64| {
        (q.x - p.x) * (y - p.y) - (q.y - p.y) * (x - p.x)
    };
    let area = edge(a, b, c.x, c.y);
    if area == 0.0 || !area.is_finite() {
        return;
    }
    let clamp = |x: f64, n: u32| x.clamp(0.0, n as f64) as u32;
    // Pixel centres (u + 0.5) within the bounding box.
    let u0 = clamp((a.x.min(b.x).min(c.x) - 0.5).ceil(), w);
    let u1 = clamp((a.x.max(b.x).max(c.x) - 0.5).floor() + 1.0, w);
    let v0 = clamp((a.y.min(b.y).min(c.y) - 0.5).ceil(), h);
    let v1 = clamp((a.y.max(b.y).max(c.y) - 0.5).floor() + 1.0, h);
    for v in v0..v1 {
        let y = v as f64 + 0.5;
        for u in u0..u1 {
            let x = u as f64 + 0.5;
            let (e0, e1, e2) = (edge(b, c, x, y), edge(c, a, x, y), edge(a, b, x, y));
            let inside = if area > 0.0 {
                e0 >= 0.0 && e1 >= 0.0 && e2 >= 0.0
            } else {
                e0 <= 0.0 && e1 <= 0.0 && e2 <= 0.0
            };
            if inside {
                mask[v as usize * w as usize + u as usize] = true;
            }
        }
    }
}

/// `mask` grown by `radius_px` in every direction (a `(2r + 1)²` square): a pixel is set when
/// any pixel of its window is.
pub fn dilated(mask: &Image<bool>, radius_px: u32) -> Image<bool> {
    if radius_px == 0 {
        return mask.clone();
    }
    let (w, h) = (mask.width() as usize, mask.height() as usize);
    let sat = SummedAreaTable::from_fn(w, h, |u, v| f64::from(u8::from(mask.data()[v * w + u])));
    let r = radius_px as usize;
    let data = (0..h)
        .flat_map(|v| (0..w).map(move |u| (u, v)))
        .map(|(u, v)| {
            sat.sum(
                u.saturating_sub(r),
                v.saturating_sub(r),
                u + r + 1,
                v + r + 1,
            ) > 0.0
        })
        .collect();
    Image::from_parts(mask.width(), mask.height(), data)
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Translation3, UnitQuaternion};

    fn camera() -> PinholeIntrinsics {
        PinholeIntrinsics::new(64, 48, 100.0, 100.0, 32.0, 24.0).unwrap()
    }

    #[test]
    fn a_cube_facing_the_camera_covers_its_projected_square() {
        // A 20 mm cube 0.5 m in front: its front face spans ±10 mm at z = 0.49 m, i.e.
        // ±100·0.01/0.49 = ±2.04 px; the back face at 0.51 m is smaller. The silhouette is the
        // front face's square: centres at 32 ± {0.5, 1.5} in u, 24 ± {0.5, 1.5} in v → 4 × 4.
        let cube = TriMesh::cuboid([0.0; 3], [0.01; 3]);
        let t_c_o =
            Isometry3::from_parts(Translation3::new(0.0, 0.0, 0.5), UnitQuaternion::identity());
        let mask = silhouette_mask(&cube, &camera(), &t_c_o);
        let count = mask.data().iter().filter(|&&m| m).count();
        assert_eq!(count, 16);
        assert!(mask.get(30, 22).unwrap() && mask.get(33, 25).unwrap());
        assert!(!mask.get(29, 24).unwrap() && !mask.get(34, 24).unwrap());
        // Grown by 2 px: an 8 × 8 square.
        let grown = dilated(&mask, 2);
        assert_eq!(grown.data().iter().filter(|&&m| m).count(), 64);
    }

    #[test]
    fn a_part_behind_the_camera_has_no_silhouette() {
        let cube = TriMesh::cuboid([0.0; 3], [0.01; 3]);
        let t_c_o = Isometry3::from_parts(
            Translation3::new(0.0, 0.0, -0.5),
            UnitQuaternion::identity(),
        );
        let mask = silhouette_mask(&cube, &camera(), &t_c_o);
        assert!(mask.data().iter().all(|&m| !m));
    }
}
