//! The five parts of the paper's evaluation (the ROBI dataset's Eye Bolt, Tube Fitting, Chrome
//! Screw, Gear and Zigzag) as parametric, watertight triangle meshes of the real parts' size,
//! each with its declared symmetry group.
//!
//! Meshes are in metres in the object frame, faces counter-clockwise seen from outside. The
//! object origin is the centre of the part's bounding box and lies on every symmetry axis, as
//! [`Symmetry`] requires. Dimensions are named millimetre constants in each part's module.

mod builder;
mod chrome_screw;
mod eye_bolt;
mod gear;
mod lathe;
mod thread;
mod tube_fitting;
mod zigzag;

#[cfg(test)]
mod test_support;

use std::fmt;
use std::str::FromStr;

use crate::mesh::TriMesh;
use crate::symmetry::Symmetry;

/// One of the five evaluation parts.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Part {
    /// A lifting eye bolt: a ring on a threaded M8 shank along −z.
    EyeBolt,
    /// A hex-bodied tube fitting with a short and a long tube along z and a through bore.
    TubeFitting,
    /// An M6 × 30 pan-head screw along z, head up.
    ChromeScrew,
    /// A 20-tooth spur gear in the xy-plane with a bore.
    Gear,
    /// A sheet-metal strip bent into a Z in the xy-plane, its width along z.
    Zigzag,
}

impl Part {
    /// Every part, in the paper's order.
    pub const ALL: [Part; 5] = [
        Part::EyeBolt,
        Part::TubeFitting,
        Part::ChromeScrew,
        Part::Gear,
        Part::Zigzag,
    ];

    /// The part's name on command lines and in files.
    pub fn name(self) -> &'static str {
        match self {
            Part::EyeBolt => "eye-bolt",
            Part::TubeFitting => "tube-fitting",
            Part::ChromeScrew => "chrome-screw",
            Part::Gear => "gear",
            Part::Zigzag => "zigzag",
        }
    }

    /// The part's name as the paper writes it.
    pub fn display_name(self) -> &'static str {
        match self {
            Part::EyeBolt => "Eye Bolt",
            Part::TubeFitting => "Tube Fitting",
            Part::ChromeScrew => "Chrome Screw",
            Part::Gear => "Gear",
            Part::Zigzag => "Zigzag",
        }
    }

    /// The part's watertight mesh: metres, object frame, outward faces. Every closed shell is
    /// 2-manifold and outward; the Eye Bolt is two overlapping shells (ring and shank), the
    /// others one.
    pub fn mesh(self) -> TriMesh {
        match self {
            Part::EyeBolt => eye_bolt::mesh(),
            Part::TubeFitting => tube_fitting::mesh(),
            Part::ChromeScrew => chrome_screw::mesh(),
            Part::Gear => gear::mesh(),
            Part::Zigzag => zigzag::mesh(),
        }
    }

    /// The rotations about the object origin that leave the part looking the same, with the
    /// distance (metres) by which the surface may miss itself under them.
    pub fn symmetry(self) -> Symmetry {
        match self {
            Part::EyeBolt => eye_bolt::symmetry(),
            Part::TubeFitting => tube_fitting::symmetry(),
            Part::ChromeScrew => chrome_screw::symmetry(),
            Part::Gear => gear::symmetry(),
            Part::Zigzag => zigzag::symmetry(),
        }
    }
}

impl FromStr for Part {
    type Err = String;

    /// Parses a part's [`Part::name`].
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Part::ALL
            .into_iter()
            .find(|part| part.name() == s)
            .ok_or_else(|| {
                let names: Vec<&str> = Part::ALL.iter().map(|part| part.name()).collect();
                format!("unknown part {s:?}: expected one of {}", names.join(", "))
            })
    }
}

impl fmt::Display for Part {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_round_trip_and_are_distinct() {
        for part in Part::ALL {
            assert_eq!(part.name().parse::<Part>(), Ok(part));
            assert_eq!(part.to_string(), part.name());
        }
        let mut names: Vec<&str> = Part::ALL.iter().map(|p| p.name()).collect();
        names.sort_unstable();
        names.dedup();
        assert_eq!(names.len(), Part::ALL.len());
        let mut display: Vec<&str> = Part::ALL.iter().map(|p| p.display_name()).collect();
        display.sort_unstable();
        display.dedup();
        assert_eq!(display.len(), Part::ALL.len());
    }

    #[test]
    fn unknown_names_list_the_valid_ones() {
        for bad in ["", "Gear", "screw", "eye_bolt"] {
            let err = bad.parse::<Part>().unwrap_err();
            for part in Part::ALL {
                assert!(err.contains(part.name()), "{err}");
            }
        }
    }

    #[test]
    fn meshes_are_moderate_and_centred_on_the_origin() {
        for part in Part::ALL {
            let mesh = part.mesh();
            let triangles = mesh.triangles.len();
            assert!(
                (500..=40_000).contains(&triangles),
                "{part}: {triangles} triangles"
            );
            let report = test_support::clean_report(&mesh);
            let centre = (report.aabb_min.coords + report.aabb_max.coords) / 2.0;
            // 1 µm: the origin is the bounding box's centre by construction.
            assert!(
                centre.norm() < 1e-6,
                "{part}: bounding box centred at {centre:?} m"
            );
        }
    }
}
