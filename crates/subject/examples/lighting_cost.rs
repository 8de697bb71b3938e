//! What a sample's lightings cost with shared paths against separate ones: one dataset sample
//! (head, hair, garment, skin, every pass of the spec) rendered with its first lighting alone,
//! then with K lightings traced separately, on shared paths (one NEE shadow ray per lighting)
//! and on shared paths with one shadow ray per vertex from the mixture of the K lightings, each
//! twice with different seeds so that the noise per lighting is measured, not assumed.
//!
//! ```text
//! cargo run --release -p lightfarm-subject --example lighting_cost -- SPEC INDEX SIZE SPP [K...]
//! ```
//!
//! K defaults to 2 and 8. K = 2 is the sample's own pair; more lightings add the catalog's HDRIs
//! at further rotations. K = `olat` is the virtual light stage: the 168 OLAT discs on shared
//! paths (both NEE schedules), against one lighting and against the four brightest discs each
//! rendered alone (their noise, and a disc's own cost). Prints a markdown table for
//! BENCHMARKS.md: seconds per render, rays, cost against one lighting, and the noise per
//! lighting of each shared schedule against separate renders (per lighting, the mean over
//! covered pixels of (a − b)² / 2 between the two seeds; the ratio to separate averaged over
//! the lightings, with its range) — so "cost at equal noise" is the cost times the noise ratio.

use std::path::PathBuf;

use lightfarm_light::{EnvTransform, Hdri};
use lightfarm_render::gpu_scene::pack_scene;
use lightfarm_render::vulkan::DeviceRequest;
use lightfarm_render::{DiscLight, EnvLight, Lighting, LightingSchedule, RenderOutput, Renderer};
use lightfarm_scene::catalog::AssetKind;
use lightfarm_scene::expand::expand;
use lightfarm_scene::spec::DatasetSpec;
use lightfarm_scene::Catalog;
use lightfarm_subject::render::{load_lights, settings};

fn luminance(c: [f32; 3]) -> f64 {
    0.2126 * f64::from(c[0]) + 0.7152 * f64::from(c[1]) + 0.0722 * f64::from(c[2])
}

/// Per-pixel variance of lighting `l`, estimated from two seeds, averaged over covered pixels.
fn noise(a: &RenderOutput, b: &RenderOutput, l: usize) -> f64 {
    let (mut sum, mut n) = (0.0, 0usize);
    for p in 0..a.mask.len() {
        if a.mask[p] > 0.99 && b.mask[p] > 0.99 {
            sum += (luminance(a.lit[l][p]) - luminance(b.lit[l][p])).powi(2) / 2.0;
            n += 1;
        }
    }
    sum / n.max(1) as f64
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.len() < 4 {
        return Err("usage: lighting_cost SPEC INDEX SIZE SPP [K...]".into());
    }
    let catalog = Catalog::builtin()?;
    let spec = DatasetSpec::load(PathBuf::from(&args[0]))?.validate(&catalog)?;
    let index: u64 = args[1].parse()?;
    let size: u32 = args[2].parse()?;
    let spp: u32 = args[3].parse()?;
    // 0 stands for the OLAT basis.
    let ks: Vec<usize> = if args.len() > 4 {
        args[4..]
            .iter()
            .map(|k| if k == "olat" { Ok(0) } else { k.parse() })
            .collect::<Result<_, _>>()?
    } else {
        vec![2, 8]
    };
    let sample = expand(&spec, index)?;
    let mut assembled = lightfarm_subject::assemble(&sample, &catalog)?;
    assembled.width = size;
    assembled.height = size;
    assembled.spp = spp;
    let packed = pack_scene(&assembled.scene)?;
    let pair = load_lights(&assembled)?;
    let extra: Vec<Hdri> = catalog
        .of_kind(AssetKind::Hdri)
        .into_iter()
        .map(|h| Hdri::load(&catalog.path_of(h)))
        .collect::<Result<_, _>>()?;
    let lights = |k: usize| -> Vec<EnvLight> {
        (0..k)
            .map(|i| match pair.get(i) {
                Some(l) => l.clone(),
                None => EnvLight {
                    name: format!("extra{i}"),
                    hdri: extra[i % extra.len()].clone(),
                    transform: EnvTransform {
                        rotation_deg: 47.0 * i as f32,
                        flip: i % 2 == 1,
                    },
                },
            })
            .collect()
    };
    let mut shared = Renderer::new(&DeviceRequest::Auto)?;
    shared.set_lighting_schedule(LightingSchedule::Shared);
    let mut separate = Renderer::new(&DeviceRequest::Auto)?;
    separate.set_lighting_schedule(LightingSchedule::Separate);
    let mut mixture = Renderer::new(&DeviceRequest::Auto)?;
    mixture.set_lighting_schedule(LightingSchedule::Mixture);
    let base = settings(&assembled);
    let run = |r: &Renderer, k: usize| -> Result<[RenderOutput; 2], Box<dyn std::error::Error>> {
        let ls = lights(k);
        let mut s = base.clone();
        let a = r.render(&packed, &ls, &s, &mut |_| {})?;
        s.seed = base.seed.wrapping_add(1);
        let b = r.render(&packed, &ls, &s, &mut |_| {})?;
        Ok([a, b])
    };
    eprintln!(
        "sample {index} of {} at {size}², {spp} spp on {}: {} triangles, {} fibre segments",
        args[0],
        shared.device().name,
        packed.triangle_count,
        packed.segment_count
    );
    let seconds = |o: &[RenderOutput; 2]| (o[0].stats.seconds + o[1].stats.seconds) / 2.0;
    let one = run(&separate, 1)?;
    let t1 = seconds(&one);
    println!("| lightings | schedule | seconds per render | M rays | cost / one lighting | noise per lighting / separate (mean, range) | cost at equal noise / one lighting |");
    println!("|---|---|---|---|---|---|---|");
    println!(
        "| 1 | — | {t1:.2} | {:.1} | 1.00× | — | 1.00× |",
        one[0].stats.rays as f64 / 1e6
    );
    let discs = DiscLight::olat(&lightfarm_subject::render::olat_basis(168)?);
    let run_discs = |r: &Renderer,
                     ds: &[&DiscLight]|
     -> Result<[RenderOutput; 2], Box<dyn std::error::Error>> {
        let ls: Vec<Lighting> = ds.iter().map(|d| Lighting::Disc(d)).collect();
        let mut s = base.clone();
        s.passes.clear();
        let a = r.render_lightings(&packed, &ls, &s, &mut |_| {})?;
        s.seed = base.seed.wrapping_add(1);
        let b = r.render_lightings(&packed, &ls, &s, &mut |_| {})?;
        Ok([a, b])
    };
    for &k in &ks {
        if k == 0 {
            let all: Vec<&DiscLight> = discs.iter().collect();
            let sh = run_discs(&shared, &all)?;
            let tp = seconds(&sh);
            // The four discs that light the subject most, each alone.
            let mut order: Vec<usize> = (0..discs.len()).collect();
            let mean = |l: usize| sh[0].lit[l].iter().map(|c| luminance(*c)).sum::<f64>();
            order.sort_by(|&a, &b| mean(b).total_cmp(&mean(a)));
            let (mut t_disc, mut alone_noise) = (0.0, Vec::new());
            for &l in &order[..4] {
                let alone = run_discs(&separate, &[&discs[l]])?;
                t_disc += seconds(&alone) / 4.0;
                alone_noise.push(noise(&alone[0], &alone[1], 0));
            }
            let ratios_of = |o: &[RenderOutput; 2]| -> Vec<f64> {
                order[..4]
                    .iter()
                    .zip(&alone_noise)
                    .map(|(&l, a)| noise(&o[0], &o[1], l) / a)
                    .collect()
            };
            let ratios = ratios_of(&sh);
            let (mean_ratio, lo, hi) = spread(&ratios);
            println!(
                "| 1 OLAT disc | — | {t_disc:.2} | — | {:.2}× | — | — |",
                t_disc / t1
            );
            println!(
                "| 168 OLAT discs | shared | {tp:.2} | {:.1} | {:.2}× ({:.2}× one disc) | {mean_ratio:.2} ({lo:.2}–{hi:.2}) | {:.2}× |",
                sh[0].stats.rays as f64 / 1e6,
                tp / t1,
                tp / t_disc,
                tp / t1 * mean_ratio
            );
            // The mixture against the same four discs alone (their noise was measured above).
            let mx = run_discs(&mixture, &all)?;
            let tm = seconds(&mx);
            let (mm, mlo, mhi) = spread(&ratios_of(&mx));
            println!(
                "| 168 OLAT discs | mixture | {tm:.2} | {:.1} | {:.2}× ({:.2}× one disc) | {mm:.2} ({mlo:.2}–{mhi:.2}) | {:.2}× |",
                mx[0].stats.rays as f64 / 1e6,
                tm / t1,
                tm / t_disc,
                tm / t1 * mm
            );
            continue;
        }
        let sep = run(&separate, k)?;
        let sh = run(&shared, k)?;
        let mx = run(&mixture, k)?;
        let ratios = |o: &[RenderOutput; 2]| -> Vec<f64> {
            (0..k)
                .map(|l| noise(&o[0], &o[1], l) / noise(&sep[0], &sep[1], l))
                .collect()
        };
        let (mean, lo, hi) = spread(&ratios(&sh));
        let (mm, mlo, mhi) = spread(&ratios(&mx));
        let rays = |o: &[RenderOutput; 2]| o[0].stats.rays as f64 / 1e6;
        let (ts, tp, tm) = (seconds(&sep), seconds(&sh), seconds(&mx));
        println!(
            "| {k} | separate | {ts:.2} | {:.1} | {:.2}× | 1 | {:.2}× |",
            rays(&sep),
            ts / t1,
            ts / t1
        );
        println!(
            "| {k} | shared | {tp:.2} | {:.1} | {:.2}× | {mean:.2} ({lo:.2}–{hi:.2}) | {:.2}× |",
            rays(&sh),
            tp / t1,
            tp / t1 * mean
        );
        println!(
            "| {k} | mixture | {tm:.2} | {:.1} | {:.2}× | {mm:.2} ({mlo:.2}–{mhi:.2}) | {:.2}× |",
            rays(&mx),
            tm / t1,
            tm / t1 * mm
        );
    }
    Ok(())
}

/// Mean, min and max of the noise ratios.
fn spread(r: &[f64]) -> (f64, f64, f64) {
    let mean = r.iter().sum::<f64>() / r.len().max(1) as f64;
    let (lo, hi) = r
        .iter()
        .fold((f64::MAX, f64::MIN), |(a, b), &x| (a.min(x), b.max(x)));
    (mean, lo, hi)
}
