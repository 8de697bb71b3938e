//! Glasses: two procedural frame styles, the anchors of any glasses model, and its fit to a head.
//!
//! A glasses model is described by its [`GlassesAnchors`], found from geometry alone (the lens
//! triangles and the temples), so a downloaded model fits the same way as the procedural ones.
//! [`fit_glasses`] is the rigid-plus-uniform-scale placement; [`place_glasses`] adds what one
//! matrix cannot do: bending each temple at its hinge so its ear bend lands on that ear, as an
//! optician adjusts a frame (heads differ far more in width and depth behind the eyes than in
//! eye distance).

use glam::{DVec3, Mat3, Mat4, Vec2, Vec3};
use lightfarm_render::scene::{
    shapes, Instance, Material, MaterialModel, Mesh, ObjectClass, Scene,
};

use crate::{HeadSurface, Landmarks, SubjectError};

mod anchors;
mod fit;
mod materials;
mod mesh_builder;
mod procedural;

pub use anchors::glasses_anchors;
use anchors::lens_materials;
pub use fit::{fit_glasses, place_glasses, temple_bends, TempleBend};
pub use materials::glasses_materials;
use materials::{dark_plastic, gold, lens_material, silicone};
use mesh_builder::MeshBuilder;
pub use procedural::procedural_glasses;

/// The two procedural frame styles.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum FrameStyle {
    /// Circular lenses in a thin gold wire frame.
    Round,
    /// Rounded-rectangle lenses in a thick dark acetate frame.
    Rectangular,
}

/// Where a glasses model touches a face, in the model's own frame (after node transforms).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GlassesAnchors {
    /// Area-weighted centroid of the lens on the wearer's left.
    pub lens_left: Vec3,
    pub lens_right: Vec3,
    /// Where the left temple rests on the ear: the centre line of the temple at its ear bend,
    /// or its rearmost part when the temple is straight.
    pub ear_left: Vec3,
    pub ear_right: Vec3,
    /// Unit normal of the lens plane, pointing away from the temples (the way the wearer looks).
    pub forward: Vec3,
    /// Unit vector in the lens plane, perpendicular to the line through the lens centres.
    pub up: Vec3,
}

impl GlassesAnchors {
    /// Unit vector towards the wearer's left.
    pub fn left(&self) -> Vec3 {
        self.up.cross(self.forward)
    }

    pub fn lens_centre(&self) -> Vec3 {
        (self.lens_left + self.lens_right) * 0.5
    }
}
