//! The local shading frame: the BSDF works in coordinates where z is the normal.

use glam::Vec3;

/// An orthonormal, right-handed shading frame (`t × b = n`). In local coordinates the tangent
/// `t` is x, the bitangent `b` is y and the normal `n` is z, so a direction's z is its cos θ and
/// anisotropic roughness is measured along `t` (x) and `b` (y).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ShadingFrame {
    /// Tangent, local x: the direction of larger roughness when `anisotropic > 0`.
    pub t: Vec3,
    /// Bitangent, local y.
    pub b: Vec3,
    /// Unit normal, local z.
    pub n: Vec3,
}

impl ShadingFrame {
    /// A frame around the unit normal `n` with an arbitrary but continuous-almost-everywhere
    /// tangent (Duff et al. 2017, "Building an Orthonormal Basis, Revisited", as Mitsuba's
    /// `coordinate_system`; glam's `any_orthonormal_pair`). `n` must have unit length.
    #[inline]
    pub fn from_normal(n: Vec3) -> Self {
        let (t, b) = n.any_orthonormal_pair();
        Self { t, b, n }
    }

    /// A frame around the unit normal `n` whose tangent is `tangent` made orthogonal to `n`
    /// (Gram–Schmidt), for anisotropic materials with a meaningful direction (e.g. brushing
    /// or turning marks). Falls back to [`ShadingFrame::from_normal`] if `tangent` is (nearly)
    /// parallel to `n`, zero or not finite.
    #[inline]
    pub fn from_normal_tangent(n: Vec3, tangent: Vec3) -> Self {
        let projected = tangent - n * n.dot(tangent);
        let length_squared = projected.length_squared();
        let usable =
            length_squared > 1e-12 * tangent.length_squared() && length_squared.is_finite();
        if !usable {
            return Self::from_normal(n);
        }
        let t = projected / length_squared.sqrt();
        Self {
            t,
            b: n.cross(t),
            n,
        }
    }

    /// World → local (z along the normal).
    #[inline]
    pub fn to_local(&self, v: Vec3) -> Vec3 {
        Vec3::new(v.dot(self.t), v.dot(self.b), v.dot(self.n))
    }

    /// Local → world.
    #[inline]
    pub fn to_world(&self, v: Vec3) -> Vec3 {
        self.t * v.x + self.b * v.y + self.n * v.z
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn assert_orthonormal_right_handed(f: &ShadingFrame) {
        for v in [f.t, f.b, f.n] {
            assert!((v.length() - 1.0).abs() < 1e-5, "{f:?}");
        }
        assert!(
            f.t.dot(f.b).abs() < 1e-5 && f.t.dot(f.n).abs() < 1e-5 && f.b.dot(f.n).abs() < 1e-5
        );
        assert!((f.t.cross(f.b) - f.n).length() < 1e-5, "{f:?}");
    }

    #[test]
    fn frames_are_orthonormal_and_round_trip() {
        let normals = [
            Vec3::Z,
            -Vec3::Z,
            Vec3::X,
            Vec3::new(0.3, -0.5, 0.8).normalize(),
            Vec3::new(-1e-4, 2e-4, -1.0).normalize(),
        ];
        let v = Vec3::new(0.2, 0.7, -0.4);
        for n in normals {
            let f = ShadingFrame::from_normal(n);
            assert_orthonormal_right_handed(&f);
            assert!((f.to_local(n) - Vec3::Z).length() < 1e-5);
            assert!((f.to_world(f.to_local(v)) - v).length() < 1e-5);
        }
    }

    #[test]
    fn tangent_is_respected_or_replaced_when_degenerate() {
        let n = Vec3::new(0.0, 0.6, 0.8);
        let f = ShadingFrame::from_normal_tangent(n, Vec3::new(1.0, 0.1, 0.0));
        assert_orthonormal_right_handed(&f);
        assert!(f.t.dot(Vec3::X) > 0.99);
        for bad in [n, Vec3::ZERO, Vec3::splat(f32::NAN)] {
            let f = ShadingFrame::from_normal_tangent(n, bad);
            assert_orthonormal_right_handed(&f);
        }
    }
}
