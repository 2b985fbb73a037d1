//! Output files.

pub mod vtk;
