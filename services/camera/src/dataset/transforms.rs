//! Poses and lengths between dataset files and Glint: millimetres ↔ metres, row-major 3×3
//! rotations and 4×4 homogeneous matrices ↔ [`Isometry3`].
//!
//! A rotation read from a file is accepted when `‖RᵀR − I‖_F < 1e-4` and `det R > 0`, then
//! projected onto the nearest rotation (`U Vᵀ` of its SVD): files store rotations as 32-bit
//! floats (BOP) or to a few digits, which leaves them orthonormal only to about 1e-7.
//! Anything further off is a corrupt file or a matrix in the wrong layout, and an error.

use nalgebra::{Isometry3, Matrix3, Matrix4, Rotation3, Translation3, UnitQuaternion, Vector3};

/// Millimetres in a metre.
pub const MM_PER_M: f64 = 1000.0;

/// Largest `‖RᵀR − I‖_F` (Frobenius) a rotation read from a file may have.
pub const ORTHONORMALITY_TOLERANCE: f64 = 1e-4;

/// Largest deviation of a 4×4 matrix's last row from `(0, 0, 0, 1)`.
pub const HOMOGENEOUS_ROW_TOLERANCE: f64 = 1e-6;

/// The rotation of a row-major 3×3 matrix `[r00, r01, r02, r10, ...]`, checked and
/// re-orthonormalised (see the module doc). The error says what is wrong, in words.
pub fn rotation_from_row_major(r: &[f64; 9]) -> Result<UnitQuaternion<f64>, String> {
    if let Some(bad) = r.iter().find(|x| !x.is_finite()) {
        return Err(format!("the rotation has a non-finite entry {bad}"));
    }
    let m = Matrix3::from_row_slice(r);
    let deviation = (m.transpose() * m - Matrix3::identity()).norm();
    if deviation >= ORTHONORMALITY_TOLERANCE {
        return Err(format!(
            "not a rotation matrix: ‖RᵀR − I‖ = {deviation:.3e} (at most {ORTHONORMALITY_TOLERANCE:e} \
             allowed; the 9 numbers are read row by row)"
        ));
    }
    let det = m.determinant();
    if det <= 0.0 {
        return Err(format!(
            "not a rotation matrix: det R = {det:.6} (a reflection), a rotation has det R = +1"
        ));
    }
    let svd = m.svd(true, true);
    let (Some(u), Some(v_t)) = (svd.u, svd.v_t) else {
        return Err("the rotation matrix's SVD failed".to_owned());
    };
    let nearest = Rotation3::from_matrix_unchecked(u * v_t);
    Ok(UnitQuaternion::from_rotation_matrix(&nearest))
}

/// The row-major entries of a rotation's matrix.
pub fn row_major_from_rotation(rotation: &UnitQuaternion<f64>) -> [f64; 9] {
    let m = rotation.to_rotation_matrix().into_inner();
    let mut out = [0.0; 9];
    for row in 0..3 {
        for col in 0..3 {
            out[3 * row + col] = m[(row, col)];
        }
    }
    out
}

/// A pose from a row-major rotation and a translation in millimetres (BOP's `cam_R_m2c`,
/// `cam_t_m2c` and the like). The pose maps the same frames the file's matrix does.
pub fn isometry_from_rotation_and_mm(
    r: &[f64; 9],
    t_mm: &[f64; 3],
) -> Result<Isometry3<f64>, String> {
    let rotation = rotation_from_row_major(r)?;
    let t_m = Vector3::from_column_slice(t_mm) / MM_PER_M;
    Ok(Isometry3::from_parts(Translation3::from(t_m), rotation))
}

/// A pose's row-major rotation and its translation in millimetres.
pub fn rotation_and_mm_from_isometry(pose: &Isometry3<f64>) -> ([f64; 9], [f64; 3]) {
    let t = pose.translation.vector * MM_PER_M;
    (row_major_from_rotation(&pose.rotation), [t.x, t.y, t.z])
}

/// A pose from a row-major 4×4 homogeneous matrix with its translation in millimetres.
pub fn isometry_from_matrix4_mm(m: &[f64; 16]) -> Result<Isometry3<f64>, String> {
    let last_row = [m[12], m[13], m[14], m[15] - 1.0];
    if let Some(bad) = last_row.iter().find(|x| !x.is_finite()) {
        return Err(format!("the matrix has a non-finite entry {bad}"));
    }
    let off = last_row.iter().fold(0.0f64, |worst, x| worst.max(x.abs()));
    if off > HOMOGENEOUS_ROW_TOLERANCE {
        return Err(format!(
            "not a rigid transform: its last row is ({}, {}, {}, {}), not (0, 0, 0, 1) (the 16 \
             numbers are read row by row)",
            m[12], m[13], m[14], m[15]
        ));
    }
    let r = [m[0], m[1], m[2], m[4], m[5], m[6], m[8], m[9], m[10]];
    isometry_from_rotation_and_mm(&r, &[m[3], m[7], m[11]])
}

/// A pose as a row-major 4×4 homogeneous matrix with its translation in millimetres.
pub fn matrix4_mm_from_isometry(pose: &Isometry3<f64>) -> [f64; 16] {
    let mut m: Matrix4<f64> = pose.to_homogeneous();
    for row in 0..3 {
        m[(row, 3)] *= MM_PER_M;
    }
    let mut out = [0.0; 16];
    for row in 0..4 {
        for col in 0..4 {
            out[4 * row + col] = m[(row, col)];
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;

    fn pose() -> Isometry3<f64> {
        Isometry3::new(
            Vector3::new(0.12, -0.034, 0.65),
            Vector3::new(0.3, -1.1, 2.0),
        )
    }

    #[test]
    fn rotations_and_translations_round_trip() {
        let (r, t_mm) = rotation_and_mm_from_isometry(&pose());
        assert!((t_mm[2] - 650.0).abs() < 1e-9);
        let back = isometry_from_rotation_and_mm(&r, &t_mm).unwrap();
        assert!((back.translation.vector - pose().translation.vector).norm() < 1e-15);
        assert!(back.rotation.angle_to(&pose().rotation) < 1e-12);

        let m = matrix4_mm_from_isometry(&pose());
        assert_eq!(m[15], 1.0);
        let back = isometry_from_matrix4_mm(&m).unwrap();
        assert!((back.translation.vector - pose().translation.vector).norm() < 1e-15);
        assert!(back.rotation.angle_to(&pose().rotation) < 1e-12);
    }

    #[test]
    fn row_major_means_rows_first() {
        // A quarter turn about z maps x to y: R = [[0, -1, 0], [1, 0, 0], [0, 0, 1]].
        let r = [0.0, -1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0];
        let q = rotation_from_row_major(&r).unwrap();
        assert!((q * Vector3::x() - Vector3::y()).norm() < 1e-15);
        let back = row_major_from_rotation(&q);
        for (a, b) in back.iter().zip(&r) {
            assert!((a - b).abs() < 1e-15);
        }
    }

    #[test]
    fn float32_rotations_are_repaired_and_bad_ones_rejected() {
        let exact = row_major_from_rotation(&pose().rotation);
        let rounded = exact.map(|x| x as f32 as f64);
        let q = rotation_from_row_major(&rounded).unwrap();
        assert!(q.angle_to(&pose().rotation) < 1e-6);
        let m = q.to_rotation_matrix().into_inner();
        assert!((m.transpose() * m - Matrix3::identity()).norm() < 1e-14);

        let mut scaled = exact;
        scaled[0] *= 1.01;
        let err = rotation_from_row_major(&scaled).unwrap_err();
        assert!(err.contains("RᵀR"), "{err}");
        let reflection = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, -1.0];
        assert!(
            rotation_from_row_major(&reflection)
                .unwrap_err()
                .contains("reflection")
        );
        let mut nan = exact;
        nan[4] = f64::NAN;
        assert!(rotation_from_row_major(&nan).is_err());

        let mut m = matrix4_mm_from_isometry(&pose());
        m[14] = 0.5;
        assert!(
            isometry_from_matrix4_mm(&m)
                .unwrap_err()
                .contains("last row")
        );
    }
}
