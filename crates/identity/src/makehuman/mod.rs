//! MakeHuman (CC0) as a parametric head model: the hm08 base mesh, its compiled target set,
//! the Face Units expression pack, the high-poly eye proxy and the MPFB region masks.
//!
//! The data comes in two catalog files ([`MakeHuman::load`]): `makehuman_core.zip`, built into
//! the asset pack (base mesh, face units, eyes, masks, their licences), and `targets.npz` from
//! the `makehuman` 1.3.2 wheel on PyPI, fetched and hash-checked by
//! `scripts/fetch-models.sh`. None of MakeHuman's code is used.

pub mod bust;
pub mod macros;
pub mod obj;
pub mod proxy;
pub mod targets;

use std::io::Read;
use std::path::{Path, PathBuf};

use crate::error::{model_error, IdentityError};
use crate::eyes::{find_irises, Iris};
use crate::ict::transfer::IctFace;
use crate::ict::IctModel;
use crate::skin::maps::FaceUv;
use obj::BaseMesh;
use proxy::Proxy;
use targets::{Target, Targets};

/// A greyscale or colour image, 8 bits per channel, row 0 at the top (v = 1 in OBJ UVs).
#[derive(Clone, Debug)]
pub struct Image8 {
    pub width: u32,
    pub height: u32,
    pub channels: u8,
    pub data: Vec<u8>,
}

impl Image8 {
    /// Bilinear sample of channel `c` at OBJ UV (u, v), in [0, 1], clamped at the edges.
    pub fn sample(&self, u: f32, v: f32, c: usize) -> f32 {
        let (w, h) = (self.width as usize, self.height as usize);
        let x = (u.clamp(0.0, 1.0) * w as f32 - 0.5).clamp(0.0, (w - 1) as f32);
        let y = ((1.0 - v.clamp(0.0, 1.0)) * h as f32 - 0.5).clamp(0.0, (h - 1) as f32);
        let (x0, y0) = (x as usize, y as usize);
        let (x1, y1) = ((x0 + 1).min(w - 1), (y0 + 1).min(h - 1));
        let (fx, fy) = (x - x0 as f32, y - y0 as f32);
        let ch = usize::from(self.channels);
        let at = |x: usize, y: usize| f32::from(self.data[(y * w + x) * ch + c]) / 255.0;
        let top = at(x0, y0) * (1.0 - fx) + at(x1, y0) * fx;
        let bottom = at(x0, y1) * (1.0 - fx) + at(x1, y1) * fx;
        top * (1.0 - fy) + bottom * fy
    }
}

/// The MPFB region masks, in the base mesh's UV layout.
#[derive(Clone, Debug)]
pub struct Masks {
    pub face: Image8,
    pub lips: Image8,
    pub eyelids: Image8,
    pub ears: Image8,
}

/// Everything the generator reads, loaded once per process.
#[derive(Clone, Debug)]
pub struct MakeHuman {
    pub base: BaseMesh,
    pub targets: Targets,
    /// The 52 ARKit-named Face Units, sorted by name.
    pub face_units: Vec<(String, Target)>,
    pub eye_mesh: BaseMesh,
    pub eye_proxy: Proxy,
    /// RGBA; alpha < 0.5 is the cornea's clear part over the iris.
    pub eye_texture: Image8,
    pub masks: Masks,
    /// Per eye-mesh face: whether it is the cornea's clear part (its texture's alpha < 0.5 at
    /// the face's UV centre), the same for every person.
    pub eye_clear: Vec<bool>,
    /// Skin landmarks in the UV layout, the same for every person.
    pub face_uv: FaceUv,
    /// The two irises of `eye_texture`, which each person's iris colour replaces.
    pub irises: [Iris; 2],
    /// The ICT Face Model's identity modes carried onto `base` ([`MakeHuman::with_ict`]).
    pub ict: Option<IctFace>,
}

/// Where the two files are looked for by default, relative to the asset pack.
pub const CORE_FILE: &str = "models/makehuman_core.zip";
pub const TARGETS_FILE: &str = "models/makehuman/targets.npz";
/// The command that installs `targets.npz`.
pub const FETCH_HINT: &str =
    "run ./scripts/fetch-models.sh (it downloads the makehuman==1.3.2 wheel from PyPI with pip, checks its hash and unpacks targets.npz)";

fn read_file(path: &Path) -> Result<Vec<u8>, IdentityError> {
    std::fs::read(path).map_err(|source| {
        if source.kind() == std::io::ErrorKind::NotFound {
            IdentityError::Missing {
                path: path.to_path_buf(),
                fix: FETCH_HINT.to_owned(),
            }
        } else {
            IdentityError::Io {
                path: path.to_path_buf(),
                source,
            }
        }
    })
}

fn decode_image(bytes: &[u8], path: &Path, entry: &str) -> Result<Image8, IdentityError> {
    let img = image::load_from_memory(bytes)
        .map_err(|e| model_error(path, entry, format!("not a PNG/JPEG image ({e})")))?;
    let (width, height) = (img.width(), img.height());
    let (channels, data) = match img.color().channel_count() {
        1 => (1, img.into_luma8().into_raw()),
        _ => (4, img.into_rgba8().into_raw()),
    };
    Ok(Image8 {
        width,
        height,
        channels,
        data,
    })
}

impl MakeHuman {
    /// Loads the ICT Face Model at `path` and matches it to the base mesh, so shapes with ICT
    /// coefficients can be built.
    pub fn with_ict(mut self, path: &Path) -> Result<MakeHuman, IdentityError> {
        let model = IctModel::load(path)?;
        let face = IctFace::new(model, &self.base)
            .map_err(|reason| model_error(path, "matching the MakeHuman base mesh", reason))?;
        self.ict = Some(face);
        Ok(self)
    }

    /// Loads the core archive and the target set. A missing file is an error saying how to
    /// install it; a malformed one names the entry.
    pub fn load(core: &Path, targets: &Path) -> Result<MakeHuman, IdentityError> {
        let core_bytes = read_file(core)?;
        let targets_bytes = read_file(targets)?;
        let targets_set = targets::read_npz(std::io::Cursor::new(&targets_bytes), targets)?;
        let mut zip = zip::ZipArchive::new(std::io::Cursor::new(&core_bytes))
            .map_err(|e| model_error(core, "archive", format!("not a zip file ({e})")))?;
        let mut entry = |name: &str| -> Result<Vec<u8>, IdentityError> {
            let mut f = zip
                .by_name(name)
                .map_err(|_| model_error(core, name, "missing from the archive"))?;
            let mut buf = Vec::new();
            f.read_to_end(&mut buf)
                .map_err(|e| model_error(core, name, e.to_string()))?;
            Ok(buf)
        };
        let text = |bytes: Vec<u8>, name: &str| {
            String::from_utf8(bytes).map_err(|_| model_error(core, name, "not UTF-8 text"))
        };
        let label = |name: &str| PathBuf::from(format!("{}!{name}", core.display()));
        let base = BaseMesh::parse(&text(entry("base.obj")?, "base.obj")?, &label("base.obj"))?;
        let eye_mesh = BaseMesh::parse(
            &text(entry("eyes/high-poly.obj")?, "eyes/high-poly.obj")?,
            &label("eyes/high-poly.obj"),
        )?;
        let eye_proxy = Proxy::parse(
            &text(entry("eyes/high-poly.mhclo")?, "eyes/high-poly.mhclo")?,
            &label("eyes/high-poly.mhclo"),
        )?;
        if eye_proxy.refs.len() != eye_mesh.positions.len() {
            return Err(model_error(
                core,
                "eyes/high-poly.mhclo",
                format!(
                    "{} proxy vertices for an eye mesh of {}",
                    eye_proxy.refs.len(),
                    eye_mesh.positions.len()
                ),
            ));
        }
        let eye_texture = decode_image(&entry("eyes/brown_eye.png")?, core, "eyes/brown_eye.png")?;
        let mut mask = |n: &str| -> Result<Image8, IdentityError> {
            let name = format!("masks/{n}.jpg");
            decode_image(&entry(&name)?, core, &name)
        };
        let masks = Masks {
            face: mask("face")?,
            lips: mask("lips")?,
            eyelids: mask("eyelids")?,
            ears: mask("ears")?,
        };
        let names: Vec<String> = zip
            .file_names()
            .filter_map(|n| n.strip_prefix("faceunits/")?.strip_suffix(".target"))
            .map(str::to_owned)
            .collect();
        let mut face_units = Vec::new();
        for n in names {
            let name = format!("faceunits/{n}.target");
            let mut f = zip
                .by_name(&name)
                .map_err(|_| model_error(core, &name, "unreadable"))?;
            let mut s = String::new();
            f.read_to_string(&mut s)
                .map_err(|_| model_error(core, &name, "not UTF-8 text"))?;
            face_units.push((n, targets::parse_text(&s, &label(&name))?));
        }
        face_units.sort_by(|a, b| a.0.cmp(&b.0));
        if face_units.len() != 52 {
            return Err(model_error(
                core,
                "faceunits/",
                format!("{} face units; the ARKit set has 52", face_units.len()),
            ));
        }
        check_base(&base, &label("base.obj"))?;
        check_targets(targets_set.iter(), &base, targets)?;
        check_targets(face_units.iter().map(|(n, t)| (n, t)), &base, core)?;
        let n = base.positions.len();
        let refs = eye_proxy.refs.iter().flatten().copied();
        let scale_refs = eye_proxy
            .scales
            .iter()
            .flatten()
            .flat_map(|&(a, b, _)| [a, b]);
        if let Some(i) = refs.chain(scale_refs).find(|&i| i as usize >= n) {
            return Err(model_error(
                core,
                "eyes/high-poly.mhclo",
                format!("refers to body vertex {i} but the base mesh has {n}"),
            ));
        }
        let eye_clear = eye_mesh
            .faces
            .iter()
            .map(|face| {
                let k = face.corners.len() as f32;
                let uv = |t: u32| eye_mesh.uvs.get(t as usize).copied().unwrap_or([0.0, 0.0]);
                let c = face.corners.iter().fold([0.0f32; 2], |a, &(_, t)| {
                    [a[0] + uv(t)[0] / k, a[1] + uv(t)[1] / k]
                });
                eye_texture.channels == 4 && eye_texture.sample(c[0], c[1], 3) < 0.5
            })
            .collect();
        let irises = find_irises(&eye_texture).ok_or_else(|| {
            model_error(
                core,
                "eyes/brown_eye.png",
                "no two irises (saturated discs) found in the eye texture",
            )
        })?;
        let mut model = MakeHuman {
            base,
            targets: targets_set,
            face_units,
            eye_mesh,
            eye_proxy,
            eye_texture,
            masks,
            eye_clear,
            face_uv: FaceUv::default(),
            irises,
            ict: None,
        };
        model.face_uv = FaceUv::find(&model.base).ok_or_else(|| {
            model_error(
                core,
                "base.obj",
                "no face landmarks (eyes, nose, cheeks) where hm08 has them",
            )
        })?;
        Ok(model)
    }
}

/// The groups the bust and the landmarks are cut and measured by.
const REQUIRED_GROUPS: [&str; 10] = [
    "body",
    "helper-upper-teeth",
    "helper-lower-teeth",
    "helper-tongue",
    "helper-l-eye",
    "helper-r-eye",
    "joint-head",
    "joint-spine-1",
    "joint-l-clavicle",
    "joint-l-shoulder",
];

fn check_base(base: &BaseMesh, path: &Path) -> Result<(), IdentityError> {
    match REQUIRED_GROUPS.iter().find(|g| base.group(g).is_none()) {
        Some(name) => Err(model_error(
            path,
            "groups",
            format!("no group {name:?}: is it MakeHuman's hm08 base mesh?"),
        )),
        None => Ok(()),
    }
}

/// Every target must address the base mesh, so applying one cannot fail later.
fn check_targets<'a>(
    targets: impl Iterator<Item = (&'a String, &'a Target)>,
    base: &BaseMesh,
    path: &Path,
) -> Result<(), IdentityError> {
    let n = base.positions.len() as u32;
    for (name, t) in targets {
        if let Some(i) = t.indices.iter().find(|&&i| i >= n) {
            return Err(model_error(
                path,
                name.as_str(),
                format!("moves vertex {i} but the base mesh has {n}"),
            ));
        }
    }
    Ok(())
}
