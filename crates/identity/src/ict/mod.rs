//! The ICT Face Model (light version of ICT-FaceKit, MIT, USC ICT) as a source of face shape:
//! its neutral face and 100 identity modes, principal components of light-stage scans of real
//! people registered to one topology, scaled so that N(0, 1) coefficients are a plausible
//! person.
//!
//! ICT heads stop at the throat and have no skin textures, so lightfarm does not render ICT
//! topology as a person. [`transfer`] carries the modes' displacement field onto MakeHuman's
//! base mesh instead: a synthetic person keeps MakeHuman's neck, shoulders, UV layout, eyes,
//! teeth and expression units (so garments, skin maps and expressions work unchanged), and its
//! face varies the way the scanned faces do.

pub mod transfer;

use std::path::Path;

use crate::error::{model_error, IdentityError};

/// Where the model file is in the asset pack.
pub const ICT_FILE: &str = "models/ict_face_model_light.npz";

/// The parts of the model the transfer reads (centimetres, +Y up, facing +Z).
#[derive(Clone, Debug)]
pub struct IctModel {
    pub neutral: Vec<[f32; 3]>,
    /// The skin surface (materials `M_Face` and `M_BackHead`: face, scalp, ears, neck, mouth
    /// and eye sockets), quads split into triangles.
    pub skin: Vec<[u32; 3]>,
    /// Eyeball vertices (sclera and iris) of the eye at +x and the eye at -x.
    pub eyes: [Vec<u32>; 2],
    /// Teeth, gums and tongue vertices.
    pub mouth: Vec<u32>,
    /// `modes[m][v]`: mode m's displacement of vertex v at one standard deviation (cm).
    pub modes: Vec<Vec<[f32; 3]>>,
}

type Npz = npyz::npz::NpzArchive<std::io::Cursor<Vec<u8>>>;

fn array<T: npyz::Deserialize>(
    npz: &mut Npz,
    path: &Path,
    name: &str,
) -> Result<(Vec<u64>, Vec<T>), IdentityError> {
    let file = npz
        .by_name(name)
        .map_err(|e| model_error(path, name, e.to_string()))?
        .ok_or_else(|| {
            model_error(
                path,
                name,
                "missing: not the ICT Face Model light archive (ict_face_model_light.npz)",
            )
        })?;
    let shape = file.shape().to_vec();
    let values = file
        .into_vec::<T>()
        .map_err(|e| model_error(path, name, e.to_string()))?;
    Ok((shape, values))
}

fn points(values: &[f32]) -> Vec<[f32; 3]> {
    values.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect()
}

impl IctModel {
    /// Reads the model file; an error names the array that is missing or malformed.
    pub fn load(path: &Path) -> Result<IctModel, IdentityError> {
        let bytes = std::fs::read(path).map_err(|source| {
            if source.kind() == std::io::ErrorKind::NotFound {
                IdentityError::Missing {
                    path: path.to_path_buf(),
                    fix: "it ships in the asset pack (assets/models/); restore it from the repository".into(),
                }
            } else {
                IdentityError::Io {
                    path: path.to_path_buf(),
                    source,
                }
            }
        })?;
        let mut npz = npyz::npz::NpzArchive::new(std::io::Cursor::new(bytes))
            .map_err(|e| model_error(path, "archive", format!("not an npz file ({e})")))?;
        Self::read(&mut npz, path)
    }

    fn read(npz: &mut Npz, path: &Path) -> Result<IctModel, IdentityError> {
        let bad = |what: &str, reason: String| model_error(path, what, reason);
        let (nshape, neutral) = array::<f32>(npz, path, "neutral")?;
        let n = neutral.len() / 3;
        if nshape != [n as u64, 3] || n == 0 {
            return Err(bad("neutral", format!("shape {nshape:?}; expected (n, 3)")));
        }
        if neutral.iter().any(|x| !x.is_finite()) {
            return Err(bad("neutral", "holds a non-finite coordinate".into()));
        }
        let (fshape, faces) = array::<i32>(npz, path, "faces")?;
        let nf = faces.len() / 4;
        if fshape != [nf as u64, 4] {
            return Err(bad("faces", format!("shape {fshape:?}; expected (f, 4)")));
        }
        let (mshape, material) = array::<i16>(npz, path, "face_material")?;
        if mshape != [nf as u64] {
            return Err(bad(
                "face_material",
                format!("shape {mshape:?}; expected ({nf},), one per face"),
            ));
        }
        let (_, names) = array::<String>(npz, path, "material_names")?;
        let find = |name: &str| -> Result<i16, IdentityError> {
            names
                .iter()
                .position(|m| m.trim() == name)
                .map(|i| i as i16)
                .ok_or_else(|| bad("material_names", format!("has no {name}")))
        };
        let mut skin = Vec::new();
        let mut by_material: Vec<Vec<u32>> = vec![Vec::new(); names.len()];
        let skin_ids = [find("M_Face")?, find("M_BackHead")?];
        for (f, (quad, &m)) in faces.chunks_exact(4).zip(&material).enumerate() {
            let mut corners = Vec::with_capacity(4);
            for &i in quad {
                if i < 0 {
                    continue;
                }
                let i = u32::try_from(i)
                    .ok()
                    .filter(|&i| (i as usize) < n)
                    .ok_or_else(|| bad("faces", format!("face {f} names vertex {i} of {n}")))?;
                corners.push(i);
            }
            if corners.len() < 3 {
                return Err(bad(
                    "faces",
                    format!("face {f} has {} corners", corners.len()),
                ));
            }
            let slot = usize::try_from(m)
                .ok()
                .filter(|&m| m < names.len())
                .ok_or_else(|| bad("face_material", format!("face {f} has material {m}")))?;
            by_material[slot].extend(&corners);
            if skin_ids.contains(&m) {
                for k in 1..corners.len() - 1 {
                    skin.push([corners[0], corners[k], corners[k + 1]]);
                }
            }
        }
        let vertices = |names: &[&str]| -> Result<Vec<u32>, IdentityError> {
            let mut v = Vec::new();
            for name in names {
                v.extend(&by_material[find(name)? as usize]);
            }
            v.sort_unstable();
            v.dedup();
            Ok(v)
        };
        let left = vertices(&["M_ScleraLeft", "M_IrisLeft"])?;
        let right = vertices(&["M_ScleraRight", "M_IrisRight"])?;
        let mouth = vertices(&["M_Teeth", "M_GumsTongue"])?;
        let neutral = points(&neutral);
        let mean_x = |v: &[u32]| v.iter().map(|&i| neutral[i as usize][0]).sum::<f32>();
        // The eye at +x first, whatever the file calls it.
        let eyes = if mean_x(&left) >= mean_x(&right) {
            [left, right]
        } else {
            [right, left]
        };
        if skin.is_empty() || eyes.iter().any(Vec::is_empty) || mouth.is_empty() {
            return Err(bad(
                "faces",
                "no skin, eyeball or teeth faces: not the ICT Face Model".into(),
            ));
        }

        let (ishape, modes) = array::<npyz::half::f16>(npz, path, "identity_modes")?;
        if ishape.len() != 3 || ishape[1] != n as u64 || ishape[2] != 3 || ishape[0] == 0 {
            return Err(bad(
                "identity_modes",
                format!("shape {ishape:?}; expected (modes, {n}, 3)"),
            ));
        }
        let modes: Vec<Vec<[f32; 3]>> = modes
            .chunks_exact(3 * n)
            .map(|m| {
                let m: Vec<f32> = m.iter().map(|&x| f32::from(x)).collect();
                points(&m)
            })
            .collect();
        if modes.iter().flatten().flatten().any(|x| !x.is_finite()) {
            return Err(bad("identity_modes", "holds a non-finite value".into()));
        }
        Ok(IctModel {
            neutral,
            skin,
            eyes,
            mouth,
            modes,
        })
    }

    /// The centroid of `vertices` of the neutral face.
    pub fn centroid(&self, vertices: &[u32]) -> [f32; 3] {
        let mut c = [0.0f64; 3];
        for &i in vertices {
            for (a, x) in c.iter_mut().zip(self.neutral[i as usize]) {
                *a += f64::from(x);
            }
        }
        c.map(|x| (x / vertices.len().max(1) as f64) as f32)
    }
}
