//! Proper symmetry groups of rigid parts: which object-frame rotations leave the part looking
//! the same. Pose errors are minimised over this group (see [`crate::pose_deviation`]).
//!
//! Every element is a rotation about the object frame's origin, so the origin must lie on all
//! symmetry axes (true for the five parts; for a user mesh, its frame's axes are used).

use std::f64::consts::PI;
use std::fmt;
use std::str::FromStr;

use nalgebra::{Rotation3, Unit, UnitQuaternion, Vector3};

/// A coordinate axis of the object frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Axis {
    /// The object frame's x axis.
    X,
    /// The object frame's y axis.
    Y,
    /// The object frame's z axis.
    Z,
}

impl Axis {
    /// The axis as a unit vector in the object frame.
    pub fn unit(self) -> Unit<Vector3<f64>> {
        match self {
            Axis::X => Vector3::x_axis(),
            Axis::Y => Vector3::y_axis(),
            Axis::Z => Vector3::z_axis(),
        }
    }
    fn name(self) -> &'static str {
        match self {
            Axis::X => "x",
            Axis::Y => "y",
            Axis::Z => "z",
        }
    }
}

impl FromStr for Axis {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "x" => Ok(Axis::X),
            "y" => Ok(Axis::Y),
            "z" => Ok(Axis::Z),
            other => Err(format!("unknown axis {other:?}: expected x, y or z")),
        }
    }
}

/// A symmetry group `G = D · C`: a finite group `D` of rotations (always holding the identity),
/// optionally combined with all rotations `C` about one axis. Every element of `D` maps that
/// axis onto itself or its opposite.
#[derive(Clone, Debug, PartialEq)]
pub struct Symmetry {
    discrete: Vec<UnitQuaternion<f64>>,
    continuous_axis: Option<Unit<Vector3<f64>>>,
    /// Largest distance, metres, between the surface and its image under any group element:
    /// 0 for an exact symmetry; a helical thread, say, is symmetric only up to its depth.
    pub tolerance_m: f64,
    /// The spec this group was built from, for display and files.
    spec: String,
}

/// Angle below which two rotations are the same group element, radians.
const SAME_ROTATION_RAD: f64 = 1e-6;

impl Symmetry {
    /// No symmetry: only the identity.
    pub fn none() -> Self {
        Self::from_generators(&[], None, "none".to_owned())
    }

    /// `n`-fold rotational symmetry about `axis` (cyclic group of order n).
    pub fn cyclic(axis: Axis, n: u32) -> Self {
        let g = UnitQuaternion::from_axis_angle(&axis.unit(), 2.0 * PI / n.max(1) as f64);
        Self::from_generators(&[g], None, format!("discrete:{}:{n}", axis.name()))
    }

    /// `n`-fold symmetry about `axis` plus the half-turn about `flip_axis` (dihedral, order 2n).
    pub fn dihedral(axis: Axis, n: u32, flip_axis: Axis) -> Self {
        let g = UnitQuaternion::from_axis_angle(&axis.unit(), 2.0 * PI / n.max(1) as f64);
        let flip = UnitQuaternion::from_axis_angle(&flip_axis.unit(), PI);
        Self::from_generators(
            &[g, flip],
            None,
            format!("dihedral:{}:{n}:{}", axis.name(), flip_axis.name()),
        )
    }

    /// All rotations about `axis` (a body of revolution).
    pub fn continuous(axis: Axis) -> Self {
        Self::from_generators(
            &[],
            Some(axis.unit()),
            format!("continuous:{}", axis.name()),
        )
    }

    /// The same group, declared exact only up to `tolerance_m`.
    pub fn with_tolerance(mut self, tolerance_m: f64) -> Self {
        self.tolerance_m = tolerance_m;
        self
    }

    fn from_generators(
        generators: &[UnitQuaternion<f64>],
        continuous_axis: Option<Unit<Vector3<f64>>>,
        spec: String,
    ) -> Self {
        // Closure by repeated products; the groups here have at most a few dozen elements.
        let mut elements = vec![UnitQuaternion::identity()];
        let mut frontier = elements.clone();
        while let Some(e) = frontier.pop() {
            for g in generators {
                let candidate = g * e;
                if !elements
                    .iter()
                    .any(|x| x.angle_to(&candidate) < SAME_ROTATION_RAD)
                {
                    elements.push(candidate);
                    frontier.push(candidate);
                }
            }
        }
        Self {
            discrete: elements,
            continuous_axis,
            tolerance_m: 0.0,
            spec,
        }
    }

    /// The finite part `D` of the group, identity first.
    pub fn discrete_rotations(&self) -> &[UnitQuaternion<f64>] {
        &self.discrete
    }

    /// The axis of continuous symmetry, if any.
    pub fn continuous_axis(&self) -> Option<Unit<Vector3<f64>>> {
        self.continuous_axis
    }

    /// Order of the finite part (1 for none, n for n-fold).
    pub fn discrete_order(&self) -> usize {
        self.discrete.len()
    }

    /// A finite sample of the group for numeric checks: every element of `D`, each composed
    /// with `steps` rotations about the continuous axis (evenly spaced, 0 included).
    pub fn sample(&self, steps: usize) -> Vec<Rotation3<f64>> {
        let steps = if self.continuous_axis.is_some() {
            steps.max(1)
        } else {
            1
        };
        let mut out = Vec::with_capacity(self.discrete.len() * steps);
        for d in &self.discrete {
            for k in 0..steps {
                let c = match self.continuous_axis {
                    Some(axis) => {
                        UnitQuaternion::from_axis_angle(&axis, 2.0 * PI * k as f64 / steps as f64)
                    }
                    None => UnitQuaternion::identity(),
                };
                out.push((d * c).to_rotation_matrix());
            }
        }
        out
    }
}

impl FromStr for Symmetry {
    type Err = String;
    /// Parses `none`, `continuous:AXIS`, `discrete:AXIS:N` or `dihedral:AXIS:N:FLIPAXIS`.
    fn from_str(spec: &str) -> Result<Self, Self::Err> {
        let parts: Vec<&str> = spec.split(':').collect();
        let order = |s: &str| -> Result<u32, String> {
            match s.parse::<u32>() {
                Ok(n) if (2..=360).contains(&n) => Ok(n),
                _ => Err(format!(
                    "symmetry order {s:?} in {spec:?} must be an integer from 2 to 360"
                )),
            }
        };
        match parts.as_slice() {
            ["none"] => Ok(Symmetry::none()),
            ["continuous", axis] => Ok(Symmetry::continuous(axis.parse()?)),
            ["discrete", axis, n] => Ok(Symmetry::cyclic(axis.parse()?, order(n)?)),
            ["dihedral", axis, n, flip] => {
                let (axis, flip): (Axis, Axis) = (axis.parse()?, flip.parse()?);
                if axis == flip {
                    return Err(format!(
                        "in {spec:?} the flip axis must differ from the main axis"
                    ));
                }
                Ok(Symmetry::dihedral(axis, order(n)?, flip))
            }
            _ => Err(format!(
                "unknown symmetry {spec:?}: expected none, continuous:AXIS, discrete:AXIS:N or \
                 dihedral:AXIS:N:FLIPAXIS (AXIS is x, y or z of the mesh frame)"
            )),
        }
    }
}

impl fmt::Display for Symmetry {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.spec)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn group_orders_match_their_definitions() {
        assert_eq!(Symmetry::none().discrete_order(), 1);
        assert_eq!(Symmetry::cyclic(Axis::Z, 6).discrete_order(), 6);
        assert_eq!(
            Symmetry::dihedral(Axis::Z, 20, Axis::X).discrete_order(),
            40
        );
        assert_eq!(Symmetry::continuous(Axis::Z).discrete_order(), 1);
        assert_eq!(Symmetry::continuous(Axis::Y).sample(36).len(), 36);
    }

    #[test]
    fn specs_round_trip_and_bad_specs_explain_themselves() {
        for spec in ["none", "continuous:z", "discrete:x:6", "dihedral:z:4:y"] {
            assert_eq!(spec.parse::<Symmetry>().unwrap().to_string(), spec);
        }
        for bad in [
            "",
            "discrete:z",
            "discrete:w:3",
            "discrete:z:1",
            "continuous",
            "dihedral:z:4:z",
        ] {
            let err = bad.parse::<Symmetry>().unwrap_err();
            assert!(!err.is_empty(), "{bad}");
        }
    }
}
