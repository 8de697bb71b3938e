//! Fitting an over-ear headset to the ears, and the models of its materials.

use glam::{Mat4, Vec3};
use lightfarm_render::scene::{MaterialModel, ObjectClass, Scene};

use crate::landmarks::Landmarks;

/// Gap between a cushion and the widest point of the ear, so the cushion does not cut into it.
const CUSHION_GAP_M: f32 = 0.004;
/// Gap between the inside of the headband and the top of the head (hair lies there).
const HEADBAND_GAP_M: f32 = 0.012;
/// Ear canals sit a little below the landmark (the widest point at eye height).
const CUP_BELOW_EAR_M: f32 = 0.01;

/// The headset's model → head transform. The cups are the parts farther than 60% of the
/// model's half-width from its midplane, in its lower half; they are centred on the ears and spread (or narrowed)
/// in x so their inner faces clear the ears, and the model is stretched upward when its
/// headband would otherwise cut into the crown.
pub fn fit_headset(scene: &Scene, lm: &Landmarks) -> Result<Mat4, String> {
    let mut points = Vec::new();
    for inst in &scene.instances {
        if let Some(mesh) = scene.meshes.get(inst.mesh as usize) {
            points.extend(
                mesh.positions
                    .iter()
                    .map(|p| inst.transform.transform_point3(Vec3::from(*p))),
            );
        }
    }
    let half_width = points.iter().map(|p| p.x.abs()).fold(0.0, f32::max);
    if half_width.is_nan() || half_width <= 0.0 {
        return Err("the headset has no geometry".into());
    }
    // The lower 55% of the model: the headband's ends also reach far out, higher up.
    let bottom = points.iter().map(|p| p.y).fold(f32::INFINITY, f32::min);
    let height = points.iter().map(|p| p.y).fold(f32::NEG_INFINITY, f32::max) - bottom;
    let cups: Vec<Vec3> = points
        .iter()
        .filter(|p| p.x.abs() > 0.6 * half_width && p.y < bottom + 0.55 * height)
        .copied()
        .collect();
    let has_side = |s: f32| cups.iter().any(|p| p.x * s > 0.0);
    if !has_side(1.0) || !has_side(-1.0) {
        return Err("no ear cups on both sides (parts beyond 60% of the half-width)".into());
    }
    let inner = cups.iter().map(|p| p.x.abs()).fold(f32::INFINITY, f32::min);
    let (lo, hi) = cups.iter().fold(
        (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
        |(lo, hi), p| (lo.min(*p), hi.max(*p)),
    );
    let cup_centre = Vec3::new(0.0, (lo.y + hi.y) * 0.5, (lo.z + hi.z) * 0.5);
    // The underside of the headband where it crosses the midplane: that is what must clear
    // the crown (the top of the model is its outer surface, a band-thickness higher).
    let top = points.iter().map(|p| p.y).fold(f32::NEG_INFINITY, f32::max);
    let band = points
        .iter()
        .filter(|p| p.x.abs() < 0.05 * half_width.max(0.2))
        .map(|p| p.y)
        .fold(f32::INFINITY, f32::min);
    let band = if band.is_finite() { band } else { top };

    let ear_half = (lm.ear_left.x - lm.ear_right.x) * 0.5;
    let target = Vec3::new(
        (lm.ear_left.x + lm.ear_right.x) * 0.5,
        (lm.ear_left.y + lm.ear_right.y) * 0.5 - CUP_BELOW_EAR_M,
        (lm.ear_left.z + lm.ear_right.z) * 0.5,
    );
    let sx = ((ear_half + CUSHION_GAP_M) / inner.max(1e-4)).clamp(0.7, 1.5);
    let needed = lm.crown.y + HEADBAND_GAP_M - target.y;
    let sy = (needed / (band - cup_centre.y).max(1e-4)).clamp(1.0, 1.4);
    Ok(Mat4::from_translation(target)
        * Mat4::from_scale(Vec3::new(sx, sy, 1.0))
        * Mat4::from_translation(-cup_centre))
}

/// Gives a headset's materials class headset and, unless the file's `extras.lightfarm` named a
/// model, the `metal` model (metalness at least 0.5) or `plastic` (everything else: shells,
/// cushions); both keep the file's colour and roughness.
pub fn headset_materials(scene: &mut Scene) {
    for m in scene.materials.iter_mut() {
        if m.model == MaterialModel::Gltf {
            m.apply_model(if m.metallic >= 0.5 {
                MaterialModel::Metal
            } else {
                MaterialModel::Plastic
            });
        }
        m.class = ObjectClass::Headset;
    }
}
