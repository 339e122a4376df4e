//! The five parts of the paper's evaluation as parametric watertight meshes.
