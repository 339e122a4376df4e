//! `glint eval refine`: the paper's Table I on mock-camera data; the experiment itself is
//! [`glint_eval::table1`].

use std::path::PathBuf;

use glint_eval::table1::RefineExperiment;
use glint_geometry::{LengthUnit, Symmetry};

#[derive(clap::Args)]
pub struct RefineArgs {
    /// Parts: `all` or a comma-separated list of eye-bolt, tube-fitting, chrome-screw, gear,
    /// zigzag. Ignored with --mesh.
    #[arg(long, default_value = "all")]
    pub parts: String,
    /// Run on this mesh (PLY/OBJ/STL) instead of the five parts.
    #[arg(long)]
    pub mesh: Option<PathBuf>,
    /// Unit of --mesh: mm or m.
    #[arg(long, default_value = "mm", value_parser = crate::mesh_cmd::parse_unit)]
    pub unit: LengthUnit,
    /// Symmetry of --mesh: none, continuous:z, discrete:z:6, dihedral:z:20:x (axes of the mesh frame).
    #[arg(long, default_value = "none")]
    pub symmetry: Symmetry,
    /// Bins (scenes) per part.
    #[arg(long, default_value_t = 5, value_parser = clap::value_parser!(u32).range(1..=1000))]
    pub scenes: u32,
    /// Views captured per scene (over a spherical cap above the bin).
    #[arg(long, default_value_t = 8, value_parser = clap::value_parser!(u32).range(1..=200))]
    pub views_per_scene: u32,
    /// View counts of the experiment, comma-separated; each at most --views-per-scene.
    #[arg(long, default_value = "1,2,4", value_delimiter = ',')]
    pub views: Vec<u32>,
    /// Parts per bin.
    #[arg(long, default_value_t = 8, value_parser = clap::value_parser!(u32).range(1..=40))]
    pub instances: u32,
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Camera resolution, WIDTHxHEIGHT.
    #[arg(long, default_value = "1280x1024", value_parser = crate::capture_cmd::parse_resolution)]
    pub resolution: (u32, u32),
    /// Samples per pixel of the multi-path renders.
    #[arg(long, default_value_t = 4, value_parser = clap::value_parser!(u32).range(1..=1024))]
    pub spp: u32,
    /// ICP's max correspondence distances to choose from (mm), on separate tuning scenes.
    #[arg(long, default_value = "2,5,10,20", value_delimiter = ',')]
    pub icp_distances_mm: Vec<f64>,
    /// The SDF refiner's first gates to choose from, mm, by the best 2 mm/2° rate on the same
    /// tuning scenes (each at most the SDF grid's 30 mm padding).
    #[arg(long, default_value = "10,20,30", value_delimiter = ',')]
    pub sdf_gates_mm: Vec<f64>,
    /// Tuning scenes per part for ICP's distance and the SDF refiner's gate (seeds disjoint
    /// from the evaluation's).
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..=100))]
    pub tune_scenes: u32,
    /// Tuning scenes per part on which the per-view pose bias of the NEES's last column is
    /// measured (the first --tune-scenes are the refiners' tuning scenes; seeds disjoint from
    /// the evaluation's).
    #[arg(long, default_value_t = 3, value_parser = clap::value_parser!(u32).range(1..=100))]
    pub view_bias_scenes: u32,
    /// Control experiment: paint the parts with the matte diffuse twin instead of their
    /// ground-truth metal (scenes are cached separately).
    #[arg(long)]
    pub matte: bool,
    /// Every refiner starts from the detector's pose as given, not moved along the viewing
    /// rays onto the depth first (the alignment, `glint_estimation::depth_alignment`, is on by
    /// default, as in the sessions).
    #[arg(long)]
    pub no_align_depth: bool,
    /// Patterns the mock camera projects per view; it matches over all of them (space-time
    /// windows). Default: the camera's (8, chosen by `glint eval camera` on geometry with a
    /// known answer); 1 is the single-shot camera of earlier Table I runs.
    #[arg(long, default_value_t = glint_camera::capture::DEFAULT_SHOTS, value_parser = clap::value_parser!(u32).range(1..=64))]
    pub shots: u32,
    /// The mock camera's matching window radius, px. Default: the camera's for --shots (3×3
    /// from 4 shots on, 5×5 for 2–3, 11×11 for one; from the same `glint eval camera` table).
    /// Single-shot Table I runs used 3 (7×7): on eye-bolt, gear, zigzag (2 scenes each) SDF
    /// 2 mm/2° at 4 views was 18.9 % with r = 3 against 4.5 % with r = 5.
    #[arg(long)]
    pub window_radius_px: Option<u32>,
    /// Mask erosion before refinement, px: only pixels whose window of this radius lies inside
    /// the object's mask give points (both refiners). Default: the matcher's window radius, so
    /// no point's depth was matched across a silhouette.
    #[arg(long)]
    pub erode_px: Option<u32>,
    /// Voxel size of the SDF grid, mm (the padding is 10 mm).
    #[arg(long, default_value_t = glint_estimation::refine::REFINE_SDF_VOXEL_MM)]
    pub sdf_voxel_mm: f64,
    /// Output directory (scenes are cached in DIR/scenes and reused when rerun).
    #[arg(long)]
    pub out: PathBuf,
}

pub fn run(args: &RefineArgs) -> anyhow::Result<()> {
    let parts = super::parse_parts(&args.parts)?;
    let experiment = RefineExperiment {
        parts,
        mesh: args.mesh.clone(),
        unit: args.unit,
        symmetry: args.symmetry.clone(),
        scenes: args.scenes,
        views_per_scene: args.views_per_scene,
        views: args.views.clone(),
        instances: args.instances,
        seed: args.seed,
        resolution: args.resolution,
        spp: args.spp,
        icp_distances_mm: args.icp_distances_mm.clone(),
        sdf_gates_mm: args.sdf_gates_mm.clone(),
        tune_scenes: args.tune_scenes,
        view_bias_scenes: args.view_bias_scenes,
        matte: args.matte,
        align_depth: !args.no_align_depth,
        shots: args.shots,
        window_radius_px: args
            .window_radius_px
            .unwrap_or_else(|| glint_camera::capture::default_window_radius_px(args.shots)),
        erode_px: args.erode_px,
        sdf_voxel_mm: args.sdf_voxel_mm,
        out: args.out.clone(),
    };
    let table = glint_eval::table1::run(&experiment)?;
    println!("{table}\nwrote {}", args.out.display());
    Ok(())
}
