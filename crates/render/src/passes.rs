//! The appendix passes (Yeh et al. 2022, appendix A): per lighting the light of each lobe family
//! at the first surface — `diffuse`, `specular` (dielectric and metal), `sss`, `coat`, `sheen`,
//! which sum to `lit` — and `shadow` (direct light with visibility over direct light without, 1
//! where unshadowed); once per render `id`, the object class of each pixel.

use crate::scene::ObjectClass;

/// One optional pass of a render.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Pass {
    Diffuse,
    Specular,
    Sss,
    Coat,
    Sheen,
    Shadow,
    Id,
}

impl Pass {
    pub const ALL: [Pass; 7] = [
        Pass::Diffuse,
        Pass::Specular,
        Pass::Sss,
        Pass::Coat,
        Pass::Sheen,
        Pass::Shadow,
        Pass::Id,
    ];
    /// What a render writes when nobody says otherwise (the and the paper's figure 9).
    pub const DEFAULT: [Pass; 4] = [Pass::Diffuse, Pass::Specular, Pass::Shadow, Pass::Id];

    pub fn name(self) -> &'static str {
        match self {
            Pass::Diffuse => "diffuse",
            Pass::Specular => "specular",
            Pass::Sss => "sss",
            Pass::Coat => "coat",
            Pass::Sheen => "sheen",
            Pass::Shadow => "shadow",
            Pass::Id => "id",
        }
    }

    pub fn parse(name: &str) -> Option<Pass> {
        Pass::ALL.into_iter().find(|p| p.name() == name)
    }

    /// Parses a list of pass names; the error names the bad one and the accepted names.
    pub fn parse_list<S: AsRef<str>>(names: &[S]) -> Result<Vec<Pass>, String> {
        let mut out = Vec::new();
        for n in names {
            let p = Pass::parse(n.as_ref()).ok_or_else(|| {
                format!(
                    "unknown pass '{}': use any of {}",
                    n.as_ref(),
                    Pass::ALL.map(Pass::name).join(", ")
                )
            })?;
            if !out.contains(&p) {
                out.push(p);
            }
        }
        out.sort();
        Ok(out)
    }

    /// Whether the integrator must split light by lobe family for this set.
    pub fn needs_split(passes: &[Pass]) -> bool {
        passes.iter().any(|p| *p != Pass::Id)
    }
}

/// The light-dependent passes of one lighting, row-major like the other passes.
#[derive(Clone, Debug, Default)]
pub struct LitPasses {
    pub diffuse: Vec<[f32; 3]>,
    pub specular: Vec<[f32; 3]>,
    pub sss: Vec<[f32; 3]>,
    pub coat: Vec<[f32; 3]>,
    pub sheen: Vec<[f32; 3]>,
    /// Direct light with visibility over without, at the first surface; 1 where unshadowed
    /// (and where no direct light arrives at all).
    pub shadow: Vec<f32>,
}

impl LitPasses {
    /// The pass's image when it is one of the five RGB families.
    pub fn rgb(&self, pass: Pass) -> Option<&Vec<[f32; 3]>> {
        match pass {
            Pass::Diffuse => Some(&self.diffuse),
            Pass::Specular => Some(&self.specular),
            Pass::Sss => Some(&self.sss),
            Pass::Coat => Some(&self.coat),
            Pass::Sheen => Some(&self.sheen),
            Pass::Shadow | Pass::Id => None,
        }
    }

    /// Resolves one lighting's accumulator (`PASS_VEC4S` vec4s per pixel) over `spp` samples.
    pub(crate) fn resolve(acc: &[[f32; 4]], pixels: usize, spp: f32) -> LitPasses {
        let mut out = LitPasses::default();
        let rgb = |v: [f32; 4]| [v[0] / spp, v[1] / spp, v[2] / spp];
        for p in 0..pixels {
            let b = crate::gpu_types::PASS_VEC4S * p;
            out.diffuse.push(rgb(acc[b]));
            out.specular.push(rgb(acc[b + 1]));
            out.sss.push(rgb(acc[b + 2]));
            out.coat.push(rgb(acc[b + 3]));
            out.sheen.push(rgb(acc[b + 4]));
            let (with, without) = (acc[b + 5][0], acc[b + 5][1]);
            out.shadow.push(if without > 0.0 {
                (with / without).clamp(0.0, 1.0)
            } else {
                1.0
            });
        }
        out
    }
}

/// The `id` pass's table (value → name), written into every EXR that has the pass: 0 is the
/// background, 1 + the [`ObjectClass`] index otherwise.
pub fn id_table() -> Vec<(u32, &'static str)> {
    let mut t = vec![(0, "background")];
    t.extend(ObjectClass::ALL.iter().map(|c| (*c as u32 + 1, c.name())));
    t
}
