//! Loss curves of both kinds of job as `LossPoint`s: a train run's `StepLog`s and an
//! adaptation run's `AdaptLog`s, live (from the job's observer) or read back from the run's
//! `losses.jsonl` (for a watcher that joins late or after a restart).

use std::path::Path;

use lightfarm_proto::v1 as pb;

use crate::adapt::AdaptLog;
use crate::train::{read_losses, LOSS_FILE};
use crate::StepLog;

pub(super) fn train_point(l: &StepLog) -> pb::LossPoint {
    pb::LossPoint {
        step: l.step,
        total: l.total,
        normal: l.normal,
        normal_lens: l.normal_lens,
        albedo: l.albedo,
        relit: l.relit,
        residual: l.residual.unwrap_or(0.0),
        adversarial: l.adversarial.unwrap_or(0.0),
        critic: l.critic.unwrap_or(0.0),
        samples_per_second: l.samples_per_second,
        perceptual: l.perceptual.unwrap_or(0.0),
        ..Default::default()
    }
}

pub(super) fn adapt_point(l: &AdaptLog) -> pb::LossPoint {
    pb::LossPoint {
        step: l.step,
        total: l.total,
        adversarial: l.gan.unwrap_or(0.0),
        critic: l.critic.unwrap_or(0.0),
        samples_per_second: l.photos_per_second,
        olat: l.olat.unwrap_or(0.0),
        relative: l.relative.unwrap_or(0.0),
        similarity: l.similarity.unwrap_or(0.0),
        identity: l.identity.unwrap_or(0.0),
        skipped_photos: l.skipped_photos,
        ..Default::default()
    }
}

/// The curve so far of the run in `run` (empty before the first step).
pub(super) fn read_curve(run: &Path, kind: pb::TrainJobKind) -> Vec<pb::LossPoint> {
    match kind {
        pb::TrainJobKind::Adapt => std::fs::read_to_string(run.join(LOSS_FILE))
            .map(|text| {
                text.lines()
                    .filter_map(|l| serde_json::from_str::<AdaptLog>(l).ok())
                    .map(|l| adapt_point(&l))
                    .collect()
            })
            .unwrap_or_default(),
        _ => read_losses(run)
            .map(|l| l.iter().map(train_point).collect())
            .unwrap_or_default(),
    }
}
