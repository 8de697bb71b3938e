//! Adaptation checkpoints. Each is a complete model that `relight` and `eval` load like any
//! other: the base model's `net.json` and `model.safetensors` (hard-linked, or copied where
//! links are impossible), plus `adapter.safetensors` and `adapter.json` (f_Ā's shape and
//! target), the critic and both Adam states, and `state.json`. Written to a temporary
//! directory and renamed, `latest` replaced by rename: `kill -9` at any moment leaves the
//! previous checkpoint intact. The "finetune only" ablation has no adapter: its checkpoint holds
//! the fine-tuned networks as `model.safetensors`, a plain model.

use std::fs;
use std::path::{Path, PathBuf};

use lightfarm_nets::{save_weights, AdaptTarget};
use serde::{Deserialize, Serialize};

use super::config::AdaptConfig;
use super::run::{Modules, Trainee, ADAPT_RUN_FILE};
use crate::train::{
    begin_checkpoint, publish_checkpoint, write_atomic, MODEL_FILE, NET_FILE, STATE_FILE,
};
use crate::TrainError;

pub const ADAPTER_FILE: &str = "adapter.safetensors";
/// f_Ā's shape and target next to its weights.
pub const ADAPTER_JSON: &str = "adapter.json";
pub(super) const CRITIC_FILE: &str = "critic.safetensors";
pub(super) const OPTIM_FILE: &str = "optim.bpk";
pub(super) const CRITIC_OPTIM_FILE: &str = "critic_optim.bpk";

/// `adapter.json`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AdapterFile {
    pub target: AdaptTarget,
    pub base: usize,
    pub blocks: usize,
}

#[derive(Serialize, Deserialize)]
struct State {
    step: u64,
}

/// Writes `adapt.json` on the first run; a later run must adapt the same model with the same
/// adapter, seed, batch and size, or its checkpoints would resume into the wrong run.
pub(super) fn check_run_file(cfg: &AdaptConfig) -> Result<(), TrainError> {
    let path = cfg.out.join(ADAPT_RUN_FILE);
    if let Ok(text) = fs::read_to_string(&path) {
        let old: AdaptConfig = serde_json::from_str(&text).map_err(|e| {
            TrainError::Config(format!(
                "{}: unreadable ({e}); move the run directory away",
                path.display()
            ))
        })?;
        if old.base != cfg.base
            || old.target != cfg.target
            || old.finetune != cfg.finetune
            || old.adapter != cfg.adapter
            || old.seed != cfg.seed
            || old.batch != cfg.batch
            || old.size != cfg.size
        {
            return Err(TrainError::Config(format!(
                "{} adapted another base model or adapter/seed/batch/size; resume with the same \
                 settings or give this config another `out` directory",
                cfg.out.display()
            )));
        }
    }
    let text = serde_json::to_string_pretty(cfg).map_err(|e| TrainError::Config(e.to_string()))?;
    write_atomic(&path, text.as_bytes())
}

fn link_or_copy(from: &Path, to: &Path) -> Result<(), TrainError> {
    if fs::hard_link(from, to).is_ok() {
        return Ok(());
    }
    fs::copy(from, to)
        .map(|_| ())
        .map_err(|e| TrainError::io(from, e))
}

pub(super) fn save(
    cfg: &AdaptConfig,
    step: u64,
    base_dir: &Path,
    shape: &AdapterFile,
    (trainee, critic, optim, critic_optim): Modules<'_>,
) -> Result<PathBuf, TrainError> {
    let tmp = begin_checkpoint(&cfg.out, step)?;
    let ck = |e: String| TrainError::Checkpoint(e);
    link_or_copy(&base_dir.join(NET_FILE), &tmp.join(NET_FILE))?;
    match trainee {
        Trainee::Adapter(adapter) => {
            link_or_copy(&base_dir.join(MODEL_FILE), &tmp.join(MODEL_FILE))?;
            save_weights(adapter, &tmp.join(ADAPTER_FILE)).map_err(|e| ck(e.to_string()))?;
            let json = serde_json::to_vec_pretty(shape).map_err(|e| ck(e.to_string()))?;
            write_atomic(&tmp.join(ADAPTER_JSON), &json)?;
        }
        Trainee::Finetune(net) => {
            save_weights(net, &tmp.join(MODEL_FILE)).map_err(|e| ck(e.to_string()))?;
        }
    }
    save_weights(critic, &tmp.join(CRITIC_FILE)).map_err(|e| ck(e.to_string()))?;
    optim
        .save(tmp.join(OPTIM_FILE))
        .map_err(|e| ck(format!("optimizer state: {e:?}")))?;
    critic_optim
        .save(tmp.join(CRITIC_OPTIM_FILE))
        .map_err(|e| ck(format!("critic optimizer state: {e:?}")))?;
    let state = serde_json::to_vec(&State { step }).map_err(|e| ck(e.to_string()))?;
    write_atomic(&tmp.join(STATE_FILE), &state)?;
    publish_checkpoint(&cfg.out, step, cfg.keep_checkpoints)
}

pub(super) fn load_step(dir: &Path) -> Result<u64, TrainError> {
    let path = dir.join(STATE_FILE);
    let state: State =
        serde_json::from_slice(&fs::read(&path).map_err(|e| TrainError::io(&path, e))?)
            .map_err(|e| TrainError::Checkpoint(format!("{}: {e}", path.display())))?;
    Ok(state.step)
}
