//! `lightfarm relight-olat`: a sample rendered with its OLAT images (`olat = 168` under
//! `[lighting]`) relit under any HDRI as the weighted sum of those images, the way a physical
//! light stage relights a subject (Debevec et al. 2000). One render yields any number of
//! lightings.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use clap::Args;
use exr::prelude::*;
use lightfarm_light::{EnvTransform, Hdri, OlatBasis};
use lightfarm_render::output::{tonemap_srgb8, write_rgb8_png};
use lightfarm_trainer::olat_sample::decode_olat;

/// The lighting to relight under, as `relight` and `relight-olat` take it.
#[derive(Args, Debug)]
pub struct TargetHdri {
    /// Target lighting: an .hdr/.exr file or an HDRI id of the asset catalog.
    #[arg(long)]
    pub hdri: String,
    /// Rotation of the HDRI about +Y, degrees.
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    pub rotation: f32,
    /// Mirror the HDRI left-right.
    #[arg(long)]
    pub flip: bool,
    /// Asset catalog for HDRI ids (default: the built-in pack).
    #[arg(long)]
    pub assets: Option<PathBuf>,
}

#[derive(Args)]
pub struct RelightOlatArgs {
    /// A sample EXR with OLAT layers (olat000.R ...).
    pub sample: PathBuf,
    #[command(flatten)]
    pub target: TargetHdri,
    /// The relit image: linear RGB OpenEXR (R, G, B, A = the sample's mask).
    #[arg(long)]
    pub out: PathBuf,
    /// Also a tone-mapped sRGB preview.
    #[arg(long)]
    pub png: Option<PathBuf>,
}

/// An HDRI given as a file or a catalog id.
pub(crate) fn hdri_path(hdri: &str, assets: &Option<PathBuf>) -> Result<PathBuf> {
    let path = Path::new(hdri);
    if path.exists() {
        return Ok(path.to_path_buf());
    }
    let catalog = crate::spec_cmd::load_catalog(assets)?;
    match catalog.get(hdri) {
        Some(a) if a.kind == lightfarm_scene::AssetKind::Hdri => Ok(catalog.path_of(a)),
        _ => bail!(
            "--hdri {hdri}: neither a file nor an HDRI id of the catalog (`lightfarm assets \
             list` shows them)"
        ),
    }
}

pub fn run(a: RelightOlatArgs) -> Result<()> {
    crate::render_cmd::ensure_parent(&a.out, "--out")?;
    if let Some(p) = &a.png {
        crate::render_cmd::ensure_parent(p, "--png")?;
    }
    let path = hdri_path(&a.target.hdri, &a.target.assets)?;
    let name = a.sample.display().to_string();
    let bytes = std::fs::read(&a.sample).with_context(|| format!("reading {name}"))?;
    let olat = decode_olat(&bytes, &name)?;
    let env = Hdri::load(&path).with_context(|| format!("--hdri {}", path.display()))?;
    // The basis the worker rendered (lightfarm_subject::render::olat_basis).
    let basis = lightfarm_subject::render::olat_basis(olat.lights.len() as u32)?;
    let transform = EnvTransform {
        rotation_deg: a.target.rotation,
        flip: a.target.flip,
    };
    let relit = relight(&basis, &env, &transform, &olat.lights)?;
    write_rgba_exr(&a.out, olat.width, olat.height, &relit, &olat.mask)?;
    if let Some(p) = &a.png {
        write_rgb8_png(
            p,
            olat.width as u32,
            olat.height as u32,
            &tonemap_srgb8(&relit, &olat.mask),
        )?;
    }
    println!(
        "relit {name} under {} ({} OLAT images) -> {}",
        path.display(),
        olat.lights.len(),
        a.out.display()
    );
    Ok(())
}

/// Σ weightᵢ × imageᵢ, the weights being `env`'s projection onto the basis.
pub fn relight(
    basis: &OlatBasis,
    env: &Hdri,
    transform: &EnvTransform,
    images: &[Vec<[f32; 3]>],
) -> Result<Vec<[f32; 3]>> {
    let weights = basis.weights(env, transform);
    let refs: Vec<&[[f32; 3]]> = images.iter().map(|v| v.as_slice()).collect();
    Ok(basis.relight(&weights, &refs)?)
}

fn write_rgba_exr(
    path: &Path,
    width: usize,
    height: usize,
    rgb: &[[f32; 3]],
    mask: &[f32],
) -> Result<()> {
    let list = vec![
        AnyChannel::new("R", FlatSamples::F32(rgb.iter().map(|p| p[0]).collect())),
        AnyChannel::new("G", FlatSamples::F32(rgb.iter().map(|p| p[1]).collect())),
        AnyChannel::new("B", FlatSamples::F32(rgb.iter().map(|p| p[2]).collect())),
        AnyChannel::new("A", FlatSamples::F32(mask.to_vec())),
    ];
    let channels = AnyChannels::sort(list.into());
    let layer = Layer::new(
        (width, height),
        LayerAttributes::default(),
        Encoding::SMALL_LOSSLESS,
        channels,
    );
    let mut tmp = path.as_os_str().to_owned();
    tmp.push(format!(".tmp{}", std::process::id()));
    let tmp = PathBuf::from(tmp);
    Image::from_layer(layer)
        .write()
        .to_file(&tmp)
        .with_context(|| format!("writing {}", path.display()))?;
    std::fs::rename(&tmp, path).with_context(|| format!("writing {}", path.display()))
}
