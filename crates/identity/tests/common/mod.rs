//! The model files of the asset pack (`targets.npz` is installed by scripts/fetch-models.sh,
//! which scripts/test.sh runs first; a missing file fails the test with that command).
#![allow(dead_code)]

use std::path::PathBuf;
use std::sync::OnceLock;

use lightfarm_identity::ict::ICT_FILE;
use lightfarm_identity::makehuman::{MakeHuman, CORE_FILE, TARGETS_FILE};

pub fn assets() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../assets")
}

pub fn model() -> &'static MakeHuman {
    static MODEL: OnceLock<MakeHuman> = OnceLock::new();
    MODEL.get_or_init(|| {
        MakeHuman::load(&assets().join(CORE_FILE), &assets().join(TARGETS_FILE))
            .and_then(|m| m.with_ict(&assets().join(ICT_FILE)))
            .unwrap_or_else(|e| panic!("{e}"))
    })
}
