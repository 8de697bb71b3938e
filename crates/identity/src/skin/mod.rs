//! Skin colour: chromophore concentrations → diffuse albedo, and its maps in the mesh's UVs.

pub mod chromophore;
pub mod maps;
pub mod noise;
pub mod spectra;
