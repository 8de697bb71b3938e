//! Checks that an assembled subject is a plausible person, for robustness runs over many
//! generated identities (`lightfarm people check`, the identity tests): finite geometry, unit
//! normals, both eyes inside the head, and no skin through the garment.

use glam::{Mat4, Vec3};
use lightfarm_render::scene::{ObjectClass, Scene};

use crate::assemble::Assembled;

/// Skin vertices a fit may leave outside the cloth (the cover map works in 1 cm × 5° bins, so
/// a vertex at a sleeve's edge can read as outside); more is a garment inside the body.
pub const MAX_SKIN_THROUGH_GARMENT: usize = 3;

/// The world-space points of the scene's triangles whose material has `class`.
fn points_of(scene: &Scene, class: ObjectClass) -> Vec<Vec3> {
    let mut out = Vec::new();
    for inst in &scene.instances {
        let Some(mesh) = scene.meshes.get(inst.mesh as usize) else {
            continue;
        };
        let t: Mat4 = inst.transform;
        for (k, tri) in mesh.indices.chunks_exact(3).enumerate() {
            let m = mesh.triangle_materials.get(k).copied().unwrap_or(0);
            if scene.materials.get(m as usize).map(|m| m.class) != Some(class) {
                continue;
            }
            for &v in tri {
                if let Some(p) = mesh.positions.get(v as usize) {
                    out.push(t.transform_point3(Vec3::from(*p)));
                }
            }
        }
    }
    out
}

/// Every problem found in `a`, each a sentence; empty when it passes.
pub fn check_assembly(a: &Assembled) -> Vec<String> {
    let mut problems = Vec::new();
    for m in &a.scene.meshes {
        if let Some(i) = m
            .positions
            .iter()
            .position(|p| !p.iter().all(|x| x.is_finite()))
        {
            problems.push(format!("mesh {:?}: vertex {i} is not finite", m.name));
        }
        let bad_normal = m.normals.iter().position(|n| {
            let l = n[0] * n[0] + n[1] * n[1] + n[2] * n[2];
            !l.is_finite() || (l - 1.0).abs() > 2e-3
        });
        if let Some(i) = bad_normal {
            problems.push(format!(
                "mesh {:?}: normal {i} is {:?}, not a unit vector",
                m.name, m.normals[i]
            ));
        }
    }
    let skin = points_of(&a.scene, ObjectClass::Skin);
    if skin.is_empty() {
        problems.push("no skin".into());
        return problems;
    }
    let eyes = points_of(&a.scene, ObjectClass::Eyes);
    if eyes.is_empty() {
        problems.push("no eyes".into());
        return problems;
    }
    // The head's skin: 13 cm below to 15 cm above the eyes (chin to crown), not the shoulders.
    let eye_y = eyes.iter().map(|p| p.y).sum::<f32>() / eyes.len() as f32;
    let (lo, hi) = skin
        .iter()
        .filter(|p| (eye_y - 0.13..eye_y + 0.15).contains(&p.y))
        .fold(
            (Vec3::splat(f32::MAX), Vec3::splat(f32::MIN)),
            |(lo, hi), p| (lo.min(*p), hi.max(*p)),
        );
    for (side, name) in [(true, "right"), (false, "left")] {
        // The canonical frame faces +Z with +X to the head's left.
        let pts: Vec<Vec3> = eyes
            .iter()
            .copied()
            .filter(|p| (p.x < 0.0) == side)
            .collect();
        if pts.is_empty() {
            problems.push(format!("no {name} eye"));
            continue;
        }
        let c = pts.iter().copied().sum::<Vec3>() / pts.len() as f32;
        if c.cmplt(lo).any() || c.cmpgt(hi).any() {
            problems.push(format!(
                "the {name} eye's centre {c:?} is outside the head's skin {lo:?}..{hi:?}"
            ));
        }
    }
    if a.stats.skin_through_garment > MAX_SKIN_THROUGH_GARMENT {
        problems.push(format!(
            "{} skin vertices show through the garment (at most {MAX_SKIN_THROUGH_GARMENT} allowed)",
            a.stats.skin_through_garment
        ));
    }
    problems
}
