//! `lightfarm eval`: relight every sample of a split (lit0 → lighting 1) and score the result
//! against the render (MAE, MSE, SSIM on display values) plus the SH lighting-recovery error of
//! section 5.2, and LPIPS when the user supplies its weights. A first row scores the unrelit
//! input, the floor any model must beat.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use burn::prelude::*;
use lightfarm_nets::metrics::{fit_sh_irradiance, mae, mse, sphere_error, ssim, Planar};
use lightfarm_nets::Lpips;
use lightfarm_scene::Catalog;
use serde::Serialize;

use crate::data::Dataset;
use crate::infer::load_model;
use crate::lights::{camera_to_env, LightCache};
use crate::TrainError;

#[derive(Clone, Debug, Serialize)]
pub struct EvalRow {
    pub model: String,
    pub render_net: String,
    pub samples: usize,
    pub mae: f64,
    pub mse: f64,
    pub ssim: f64,
    /// Mean relative L1 of diffuse spheres lit by the recovered vs the true SH lighting; None
    /// for the input row (it predicts no albedo or normals).
    pub sh_error: Option<f64>,
    /// LPIPS (VGG) on display values; None without `--lpips` weights.
    pub lpips: Option<f64>,
}

/// LPIPS weights loaded on a device, scoring display images.
struct LpipsScorer {
    net: Lpips,
    device: Device,
}

impl LpipsScorer {
    fn load(path: &Path, device: &str) -> Result<Self, TrainError> {
        let device = lightfarm_nets::device::select(device)
            .map_err(|e| TrainError::Config(e.to_string()))?;
        let net =
            Lpips::load(path, &device).map_err(|e| TrainError::Config(format!("--lpips: {e}")))?;
        Ok(LpipsScorer { net, device })
    }

    fn score(&self, a: &Planar, b: &Planar) -> Result<f64, TrainError> {
        // VGG halves the image four times before its last tap.
        if a.width < 16 || a.height < 16 {
            return Err(TrainError::Config(format!(
                "LPIPS needs images of at least 16×16 px; these are {}×{}",
                a.width, a.height
            )));
        }
        let t = |p: &Planar| {
            Tensor::<4>::from_data(
                TensorData::new(p.data.clone(), [1, p.channels, p.height, p.width]),
                &self.device,
            )
        };
        Ok(f64::from(
            self.net.distance(t(a), t(b)).into_scalar::<f32>(),
        ))
    }
}

pub(crate) fn planar(rgb: &[[f32; 3]], width: usize, height: usize) -> Planar {
    let mut data = vec![0f32; 3 * width * height];
    for (i, p) in rgb.iter().enumerate() {
        for c in 0..3 {
            data[c * width * height + i] = p[c];
        }
    }
    Planar {
        width,
        height,
        channels: 3,
        data,
    }
}

fn scaled(rgb: &[[f32; 3]], s: f32) -> Vec<[f32; 3]> {
    rgb.iter().map(|p| p.map(|v| v * s)).collect()
}

/// Scores `models` (run or checkpoint directories) on `split` of the folder export `dataset`.
pub fn evaluate(
    models: &[PathBuf],
    dataset: &Path,
    split: &str,
    catalog: Catalog,
    device: &str,
    lpips: Option<&Path>,
    mut progress: impl FnMut(usize, usize),
) -> Result<Vec<EvalRow>, TrainError> {
    let data = Dataset::open(dataset, split)?;
    let lights = Arc::new(LightCache::new(catalog));
    let loaded = models
        .iter()
        .map(|m| load_model(m, device))
        .collect::<Result<Vec<_>, _>>()?;
    let lpips = lpips.map(|p| LpipsScorer::load(p, device)).transpose()?;
    let mut sums = vec![[0f64; 5]; loaded.len() + 1];
    let mut sh_counts = vec![0usize; loaded.len() + 1];
    for i in 0..data.len() {
        progress(i, data.len());
        let s = data.load(i)?;
        let (w, h) = (s.width, s.height);
        let l0 = lights.get(&s.spec.lighting[0])?;
        let l1 = lights.get(&s.spec.lighting[1])?;
        let target = planar(&scaled(&s.lit[1], l1.scale), w, h).display();
        // Section 5.2 fits the lighting on skin: the id pass's skin where the sample has it.
        let mask = Planar {
            width: w,
            height: h,
            channels: 1,
            data: s.skin.clone().unwrap_or_else(|| s.mask.clone()),
        };
        let input = planar(&scaled(&s.lit[0], l0.scale), w, h).display();
        sums[0][0] += mae(&input, &target);
        sums[0][1] += mse(&input, &target);
        sums[0][2] += ssim(&input, &target);
        if let Some(l) = &lpips {
            sums[0][4] += l.score(&input, &target)?;
        }
        let rot = camera_to_env(s.spec.camera.camera_to_world(), &s.spec.lighting[1], false);
        for (k, model) in loaded.iter().enumerate() {
            let r = model.relight(&s.lit[0], &s.mask, w, h, &l1, rot)?;
            let pred = planar(&r.relit, w, h).display();
            let row = &mut sums[k + 1];
            row[0] += mae(&pred, &target);
            row[1] += mse(&pred, &target);
            row[2] += ssim(&pred, &target);
            if let Some(l) = &lpips {
                row[4] += l.score(&pred, &target)?;
            }
            let fit = fit_sh_irradiance(
                &planar(&r.relit, w, h),
                &planar(&r.albedo, w, h),
                &planar(&r.normal, w, h),
                &mask,
            );
            if let Some(est) = fit {
                let mul = |n: [f32; 3]| {
                    [0, 1, 2].map(|i| rot[i][0] * n[0] + rot[i][1] * n[1] + rot[i][2] * n[2])
                };
                row[3] +=
                    sphere_error(&est, |n| l1.env.sh.irradiance(mul(n)).map(|v| v * l1.scale));
                sh_counts[k + 1] += 1;
            }
        }
    }
    progress(data.len(), data.len());
    let n = data.len() as f64;
    let mut rows = vec![EvalRow {
        model: "input (not relit)".into(),
        render_net: "-".into(),
        samples: data.len(),
        mae: sums[0][0] / n,
        mse: sums[0][1] / n,
        ssim: sums[0][2] / n,
        sh_error: None,
        lpips: lpips.as_ref().map(|_| sums[0][4] / n),
    }];
    for (k, model) in loaded.iter().enumerate() {
        let s = &sums[k + 1];
        rows.push(EvalRow {
            model: models[k].display().to_string(),
            render_net: serde_json::to_value(model.config.render_net)
                .ok()
                .and_then(|v| v.as_str().map(str::to_owned))
                .unwrap_or_default(),
            samples: data.len(),
            mae: s[0] / n,
            mse: s[1] / n,
            ssim: s[2] / n,
            sh_error: (sh_counts[k + 1] > 0).then(|| s[3] / sh_counts[k + 1] as f64),
            lpips: lpips.as_ref().map(|_| s[4] / n),
        });
    }
    Ok(rows)
}

/// A model's path for a 40-character table column: its end, where long paths differ.
pub(crate) fn model_column(model: &str) -> String {
    let chars: Vec<char> = model.chars().collect();
    if chars.len() > 40 {
        format!("…{}", chars[chars.len() - 39..].iter().collect::<String>())
    } else {
        model.to_owned()
    }
}

/// The rows as an aligned text table.
pub fn table(rows: &[EvalRow]) -> String {
    let with_lpips = rows.iter().any(|r| r.lpips.is_some());
    let mut out = format!(
        "{:<40} {:>11} {:>8} {:>8} {:>8} {:>8} {:>9}{}\n",
        "model",
        "render net",
        "samples",
        "MAE",
        "MSE",
        "SSIM",
        "SH error",
        if with_lpips { "    LPIPS" } else { "" }
    );
    for r in rows {
        let name = model_column(&r.model);
        out.push_str(&format!(
            "{:<40} {:>11} {:>8} {:>8.4} {:>8.4} {:>8.4} {:>9}{}\n",
            name,
            r.render_net,
            r.samples,
            r.mae,
            r.mse,
            r.ssim,
            r.sh_error.map_or("-".to_owned(), |e| format!("{e:.4}")),
            r.lpips.map_or(String::new(), |l| format!(" {l:>8.4}"))
        ));
    }
    out
}
