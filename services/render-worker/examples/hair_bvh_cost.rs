//! Where a sample's fibre BVH build goes, stage by stage: the strands cut into segments and
//! pieces, their boxes, obvhs' PLOC build, its reinsertion pass, the conversion to the 8-wide
//! compressed BVH, and the segment records in BVH order, for each curve set of samples
//! FIRST..FIRST+COUNT of a spec. These are the steps of `gpu_curves::pack_curve_set`, with the
//! same build parameters, timed one by one; the nodes' BLAKE3 shows that a build setting (such as
//! the thread count, `RAYON_NUM_THREADS`) leaves the BVH as it was.
//!
//! ```text
//! cargo run --release -p lightfarm-worker --example hair_bvh_cost -- SPEC FIRST COUNT
//! ```

use std::path::PathBuf;
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};
use lightfarm_render::gpu_curves::{build_params, bvh_pieces, segments_of, Segment, SEGMENT_VEC4S};
use lightfarm_scene::expand::expand;
use lightfarm_scene::spec::DatasetSpec;
use lightfarm_scene::Catalog;
use obvhs::aabb::Aabb;
use obvhs::bvh2::reinsertion::ReinsertionOptimizer;
use obvhs::cwbvh::builder::build_cwbvh;
use obvhs::cwbvh::bvh2_to_cwbvh::bvh2_to_cwbvh;
use obvhs::ploc::PlocBuilder;

const USAGE: &str = "usage: hair_bvh_cost SPEC FIRST COUNT";

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.len() != 3 {
        bail!("{USAGE}");
    }
    let spec_path = PathBuf::from(&args[0]);
    let num = |i: usize, what: &str| -> Result<u64> {
        args[i]
            .parse()
            .with_context(|| format!("{what} '{}' is not a whole number ({USAGE})", args[i]))
    };
    let (first, count) = (num(1, "FIRST")?, num(2, "COUNT")?);
    let catalog = Catalog::builtin()?;
    let spec = DatasetSpec::load(&spec_path)
        .with_context(|| format!("spec {}", spec_path.display()))?
        .validate(&catalog)
        .with_context(|| format!("spec {}", spec_path.display()))?;
    println!("rayon threads: {}", rayon_threads());
    println!("| sample | curves | pieces | segments + pieces s | boxes s | PLOC s | reinsertion s | to CWBVH s | records s | all s | nodes BLAKE3 |");
    println!("|---|---|---|---|---|---|---|---|---|---|---|");
    let p = build_params();
    for index in first..first + count {
        let assembled = lightfarm_subject::assemble(&expand(&spec, index)?, &catalog)
            .with_context(|| format!("sample {index}"))?;
        for c in &assembled.scene.curves {
            let t0 = Instant::now();
            let (whole, owner) = segments_of(c);
            if whole.is_empty() {
                continue;
            }
            let (segments, _) = bvh_pieces(&whole, &owner);
            let t1 = Instant::now();
            let boxes: Vec<Aabb> = segments.iter().map(Segment::aabb).collect();
            let t2 = Instant::now();
            let mut bvh2 = PlocBuilder::with_capacity(boxes.len()).build(
                p.ploc_search_distance,
                &boxes,
                (0..boxes.len() as u32).collect::<Vec<_>>(),
                p.sort_precision,
                p.search_depth_threshold,
            );
            let t3 = Instant::now();
            ReinsertionOptimizer::default().run(&mut bvh2, p.reinsertion_batch_ratio, None);
            let t4 = Instant::now();
            let bvh = bvh2_to_cwbvh(&bvh2, p.max_prims_per_leaf.clamp(1, 3), true, false);
            let t5 = Instant::now();
            let mut records = Vec::with_capacity(segments.len() * SEGMENT_VEC4S);
            for &prim in &bvh.primitive_indices {
                records.extend(segments[prim as usize].gpu_words());
            }
            let t6 = Instant::now();
            std::hint::black_box(&records);
            // The stages must be the build the worker runs, or their times say nothing of it.
            let whole_build = build_cwbvh(&boxes, p, &mut Duration::default());
            if whole_build.nodes != bvh.nodes
                || whole_build.primitive_indices != bvh.primitive_indices
            {
                bail!(
                    "sample {index}, curves '{}': the staged build differs from obvhs' \
                     build_cwbvh with the same parameters; update this example's stages",
                    c.name
                );
            }
            let s = |a: Instant, b: Instant| (b - a).as_secs_f64();
            let hash = blake3::hash(bytemuck::cast_slice(&bvh.nodes)).to_hex();
            println!(
                "| {index} | {} | {} | {:.3} | {:.3} | {:.3} | {:.3} | {:.3} | {:.3} | {:.3} | {} |",
                c.name,
                segments.len(),
                s(t0, t1),
                s(t1, t2),
                s(t2, t3),
                s(t3, t4),
                s(t4, t5),
                s(t5, t6),
                s(t0, t6),
                &hash[..16]
            );
        }
    }
    Ok(())
}

fn rayon_threads() -> String {
    std::env::var("RAYON_NUM_THREADS").unwrap_or_else(|_| "all cores".into())
}
