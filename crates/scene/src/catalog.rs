//! The asset catalog: `assets/catalog.toml`, one `[[asset]]` table per file.
//!
//! Jobs refer to assets by catalog id (or by selectors over ids and tags), never by path, so a
//! dataset spec stays valid when files move, and every file is pinned by its BLAKE3 hash so two
//! workers cannot silently render different bytes under the same id.

use std::collections::{BTreeMap, HashMap};
use std::fs::File;
use std::path::{Component, Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::error::SceneError;

/// Environment variable naming a directory whose `catalog.toml` replaces the built-in one.
pub const ASSETS_ENV: &str = "LIGHTFARM_ASSETS";

/// The catalog file's name inside an asset directory.
pub const CATALOG_FILE: &str = "catalog.toml";

/// What an asset is; decides which part of a job may select it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum AssetKind {
    Head,
    Hdri,
    Garment,
    Glasses,
    Headset,
    /// Data of a parametric model that generates assets (the MakeHuman head model).
    Model,
}

impl AssetKind {
    /// Every kind, in the order error messages list them.
    pub const ALL: [AssetKind; 6] = [
        AssetKind::Head,
        AssetKind::Hdri,
        AssetKind::Garment,
        AssetKind::Glasses,
        AssetKind::Headset,
        AssetKind::Model,
    ];

    /// The name used in `catalog.toml`.
    pub fn as_str(self) -> &'static str {
        match self {
            AssetKind::Head => "head",
            AssetKind::Hdri => "hdri",
            AssetKind::Garment => "garment",
            AssetKind::Glasses => "glasses",
            AssetKind::Headset => "headset",
            AssetKind::Model => "model",
        }
    }
}

impl std::fmt::Display for AssetKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

/// One catalog entry.
#[derive(Clone, Debug, Serialize, Deserialize)]
// Unknown keys are rejected so that a typo (`licence`, `identiy`) is an error rather than a
// silently missing value.
#[serde(deny_unknown_fields)]
pub struct Asset {
    pub id: String,
    pub kind: AssetKind,
    /// Relative to the catalog's directory, `/`-separated.
    pub path: String,
    /// Lower-case hex of the file's BLAKE3 hash (64 characters).
    pub blake3: String,
    /// SPDX identifier (or expression) of the file's licence.
    pub license: String,
    /// Credit line the licence requires; empty where none is required (CC0).
    #[serde(default)]
    pub attribution: String,
    /// Heads only: the identity a train/test split groups by (several files may show one
    /// person). Defaults to the id.
    #[serde(default)]
    pub identity: Option<String>,
    /// Free-form facts used by `tag:KEY=VALUE` selectors (gender, age_band, setting, …).
    #[serde(default)]
    pub tags: BTreeMap<String, String>,
    /// Heads not authored in the canonical head frame (metres, +Y up, face towards +Z, origin
    /// near the skull base): `canonical = scale * file + translate`.
    #[serde(default)]
    pub frame: Option<AssetFrame>,
    /// Heads without eye meshes (scans): anatomical landmarks in the canonical frame, which
    /// glasses, headsets and hair are fitted to. Heads with eye meshes have theirs detected.
    #[serde(default)]
    pub landmarks: Option<BTreeMap<String, [f64; 3]>>,
}

/// A uniform scale and a translation bringing an asset into the canonical frame.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AssetFrame {
    pub scale: f64,
    #[serde(default)]
    pub translate: [f64; 3],
}

/// The landmark names a catalog `landmarks` table must give, all of them.
pub const LANDMARK_NAMES: [&str; 6] = [
    "eye_left",
    "eye_right",
    "ear_left",
    "ear_right",
    "nose_bridge",
    "crown",
];

/// A loaded and validated catalog.
#[derive(Clone, Debug)]
pub struct Catalog {
    /// Directory asset paths are relative to (the catalog file's directory).
    pub root: PathBuf,
    pub assets: Vec<Asset>,
}

/// Top-level shape of `catalog.toml`.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct CatalogFile {
    #[serde(default)]
    asset: Vec<toml::Value>,
}

/// The built-in asset pack: `$LIGHTFARM_ASSETS` when that variable is set, otherwise the
/// repository's `assets/`.
pub fn builtin_assets_dir() -> PathBuf {
    match std::env::var_os(ASSETS_ENV) {
        Some(dir) if !dir.is_empty() => PathBuf::from(dir),
        // The pack lives in the repository, two levels above this crate; walking up with
        // parent() rather than joining "../.." keeps paths in messages readable.
        _ => {
            let manifest = Path::new(env!("CARGO_MANIFEST_DIR"));
            manifest
                .parent()
                .and_then(Path::parent)
                .map(|repo| repo.join("assets"))
                .unwrap_or_else(|| manifest.join("../../assets"))
        }
    }
}

impl Catalog {
    /// Loads and validates the catalog at `path`; asset paths resolve against its directory.
    pub fn load(path: &Path) -> Result<Catalog, SceneError> {
        let text = std::fs::read_to_string(path).map_err(|source| SceneError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        let file: CatalogFile = toml::from_str(&text).map_err(|e| SceneError::Toml {
            path: path.to_path_buf(),
            reason: format!(
                "{} (the catalog holds only `[[asset]]` tables; see the comment at its top)",
                e.message()
            ) + &location(&text, e.span()),
        })?;
        let invalid = |key: String, reason: String| SceneError::Invalid {
            path: path.to_path_buf(),
            key,
            reason,
        };

        let mut assets = Vec::with_capacity(file.asset.len());
        let mut first_use: HashMap<String, usize> = HashMap::new();
        for (i, value) in file.asset.into_iter().enumerate() {
            let mut asset = parse_asset(i, value).map_err(|(key, reason)| invalid(key, reason))?;
            validate_asset(i, &mut asset).map_err(|(key, reason)| invalid(key, reason))?;
            if let Some(j) = first_use.get(&asset.id) {
                return Err(invalid(
                    format!("asset[{i}].id"),
                    format!(
                        "duplicate id `{}` (already used by asset[{j}]): give every asset a unique id",
                        asset.id
                    ),
                ));
            }
            first_use.insert(asset.id.clone(), i);
            assets.push(asset);
        }

        let root = match path.parent() {
            Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
            _ => PathBuf::from("."),
        };
        Ok(Catalog { root, assets })
    }

    /// The built-in catalog: `catalog.toml` in [`builtin_assets_dir`].
    pub fn builtin() -> Result<Catalog, SceneError> {
        Catalog::load(&builtin_assets_dir().join(CATALOG_FILE))
    }

    /// The asset with this id.
    pub fn get(&self, id: &str) -> Option<&Asset> {
        self.assets.iter().find(|a| a.id == id)
    }

    /// All assets of one kind, in catalog order.
    pub fn of_kind(&self, kind: AssetKind) -> Vec<&Asset> {
        self.assets.iter().filter(|a| a.kind == kind).collect()
    }

    /// Selectors: `"*"` (all of that kind), an id, or `"tag:KEY=VALUE"`; the result is their
    /// union, in catalog order, without duplicates. An empty selector list selects nothing.
    /// An unknown id, an id of another kind, or a selector matching nothing of `kind` is a
    /// `SceneError::Invalid` naming `key` (the caller's spec key, e.g. `assets.heads`) and
    /// listing the valid ids.
    pub fn select(
        &self,
        kind: AssetKind,
        selectors: &[String],
        key: &str,
    ) -> Result<Vec<&Asset>, SceneError> {
        let mut chosen = vec![false; self.assets.len()];
        for selector in selectors {
            let matched = self.match_selector(kind, selector, key)?;
            if !matched.iter().any(|&m| m) {
                return Err(self.select_error(
                    kind,
                    key,
                    format!("selector `{selector}` matches no {kind} asset"),
                ));
            }
            for (c, m) in chosen.iter_mut().zip(matched) {
                *c |= m;
            }
        }
        Ok(self
            .assets
            .iter()
            .zip(chosen)
            .filter_map(|(a, c)| c.then_some(a))
            .collect())
    }

    /// Which assets (by index) one selector picks among those of `kind`.
    fn match_selector(
        &self,
        kind: AssetKind,
        selector: &str,
        key: &str,
    ) -> Result<Vec<bool>, SceneError> {
        let of_kind = |a: &Asset| a.kind == kind;
        if selector == "*" {
            return Ok(self.assets.iter().map(of_kind).collect());
        }
        if let Some(tag) = selector.strip_prefix("tag:") {
            let Some((k, v)) = tag.split_once('=') else {
                return Err(SceneError::Invalid {
                    path: self.catalog_path(),
                    key: key.to_string(),
                    reason: format!(
                        "selector `{selector}` is not of the form `tag:KEY=VALUE` \
                         (e.g. `tag:gender=f`)"
                    ),
                });
            };
            return Ok(self
                .assets
                .iter()
                .map(|a| of_kind(a) && a.tags.get(k).is_some_and(|t| t == v))
                .collect());
        }
        match self.get(selector) {
            Some(a) if a.kind == kind => Ok(self.assets.iter().map(|b| b.id == a.id).collect()),
            Some(a) => Err(self.select_error(
                kind,
                key,
                format!("`{selector}` is a {} asset, not a {kind}", a.kind),
            )),
            None => Err(self.select_error(kind, key, format!("unknown asset id `{selector}`"))),
        }
    }

    fn select_error(&self, kind: AssetKind, key: &str, what: String) -> SceneError {
        let ids: Vec<&str> = self.of_kind(kind).iter().map(|a| a.id.as_str()).collect();
        let valid = if ids.is_empty() {
            format!("the catalog has no {kind} assets")
        } else {
            format!("valid {kind} ids: {}", ids.join(", "))
        };
        SceneError::Invalid {
            path: self.catalog_path(),
            key: key.to_string(),
            reason: format!("{what}; use \"*\", an id, or \"tag:KEY=VALUE\" ({valid})"),
        }
    }

    /// Where the asset's file is on disk.
    pub fn path_of(&self, asset: &Asset) -> PathBuf {
        self.root.join(&asset.path)
    }

    /// Why `asset`'s file is absent and what fixes it: model data too large for the repository
    /// (tag `install`) names the command that installs it.
    pub fn missing_file_reason(&self, asset: &Asset) -> String {
        let file = self.path_of(asset);
        match asset.tags.get("install") {
            Some(fix) => format!(
                "file {} of asset `{}` is not installed: run {fix}",
                file.display(),
                asset.id
            ),
            None => format!(
                "file {} of asset `{}` does not exist: restore it or fix the path (relative to \
                 {})",
                file.display(),
                asset.id,
                self.root.display()
            ),
        }
    }

    /// Recomputes the BLAKE3 hash of every file; the first missing file or mismatch is an
    /// error.
    pub fn verify(&self) -> Result<(), SceneError> {
        for (i, asset) in self.assets.iter().enumerate() {
            let file = self.path_of(asset);
            let actual = hash_file(&file).map_err(|source| {
                if source.kind() == std::io::ErrorKind::NotFound {
                    SceneError::Invalid {
                        path: self.catalog_path(),
                        key: format!("asset[{i}].path"),
                        reason: self.missing_file_reason(asset),
                    }
                } else {
                    SceneError::Io {
                        path: file.clone(),
                        source,
                    }
                }
            })?;
            // Validation stored the expected hash in lower case, as to_hex() prints it.
            if actual != asset.blake3 {
                return Err(SceneError::HashMismatch {
                    path: self.catalog_path(),
                    id: asset.id.clone(),
                    file,
                    expected: asset.blake3.clone(),
                    actual,
                });
            }
        }
        Ok(())
    }

    /// The catalog file errors refer to. `Catalog` keeps only its root, so this assumes the
    /// conventional file name; `load` itself reports the real path.
    fn catalog_path(&self) -> PathBuf {
        self.root.join(CATALOG_FILE)
    }
}

/// Hex BLAKE3 of a file, streamed so that large assets need not sit in memory.
fn hash_file(path: &Path) -> std::io::Result<String> {
    let mut hasher = blake3::Hasher::new();
    hasher.update_reader(File::open(path)?)?;
    Ok(hasher.finalize().to_hex().to_string())
}

/// " at line L, column C" for a parser error span, so the message points into the file.
fn location(text: &str, span: Option<std::ops::Range<usize>>) -> String {
    let Some(start) = span.map(|s| s.start.min(text.len())) else {
        return String::new();
    };
    let before = text.get(..start).unwrap_or(text);
    let line = before.matches('\n').count() + 1;
    let column = before.rsplit('\n').next().map_or(0, |l| l.chars().count()) + 1;
    format!(" at line {line}, column {column}")
}

type KeyError = (String, String);

/// Deserialises `asset[i]`, checking `kind` first so that an unknown kind names its own key.
fn parse_asset(i: usize, value: toml::Value) -> Result<Asset, KeyError> {
    let Some(table) = value.as_table() else {
        return Err((
            format!("asset[{i}]"),
            "each asset must be a table: write it as `[[asset]]` followed by key = value lines"
                .to_string(),
        ));
    };
    if let Some(kind) = table.get("kind") {
        let known = AssetKind::ALL
            .iter()
            .any(|k| kind.as_str() == Some(k.as_str()));
        if !known {
            let names: Vec<&str> = AssetKind::ALL.iter().map(|k| k.as_str()).collect();
            return Err((
                format!("asset[{i}].kind"),
                format!(
                    "unknown kind {kind}: use one of \"{}\"",
                    names.join("\", \"")
                ),
            ));
        }
    }
    value.try_into::<Asset>().map_err(|e| {
        (
            format!("asset[{i}]"),
            format!(
                "{} (required: id, kind, path, blake3, license; optional: attribution, \
                 identity, tags, frame, landmarks)",
                e.message()
            ),
        )
    })
}

/// Checks one asset's fields and normalises them (lower-case hash, head identity default).
fn validate_asset(i: usize, asset: &mut Asset) -> Result<(), KeyError> {
    let key = |field: &str| format!("asset[{i}].{field}");
    let id_ok = |c: char| c.is_ascii_alphanumeric() || matches!(c, '_' | '-' | '.');
    if asset.id.is_empty() {
        return Err((
            key("id"),
            "must not be empty: give the asset a short unique id".into(),
        ));
    }
    // Ids share the selector namespace with "*" and "tag:…", so they are kept to a plain
    // character set that can never be mistaken for either.
    if !asset.id.chars().all(id_ok) {
        return Err((
            key("id"),
            format!(
                "`{}` contains characters other than ASCII letters, digits, `_`, `-`, `.`: \
                 rename it",
                asset.id
            ),
        ));
    }
    if asset.path.is_empty() {
        return Err((
            key("path"),
            "must not be empty: give the file's path relative to the catalog's directory".into(),
        ));
    }
    // Assets must stay inside the pack: an absolute path or `..` would make the catalog
    // depend on where it is installed.
    let escapes = Path::new(&asset.path)
        .components()
        .any(|c| !matches!(c, Component::Normal(_) | Component::CurDir));
    if escapes {
        return Err((
            key("path"),
            format!(
                "`{}` must be relative to the catalog's directory and stay inside it \
                 (no leading `/`, no `..`)",
                asset.path
            ),
        ));
    }
    if asset.blake3.len() != 64 || !asset.blake3.chars().all(|c| c.is_ascii_hexdigit()) {
        return Err((
            key("blake3"),
            format!(
                "`{}` is not 64 hex characters ({} characters given): put the file's BLAKE3 \
                 hash here (`b3sum FILE`)",
                asset.blake3,
                asset.blake3.chars().count()
            ),
        ));
    }
    asset.blake3.make_ascii_lowercase();
    if asset.license.trim().is_empty() {
        return Err((
            key("license"),
            "must not be empty: give the file's SPDX licence identifier, e.g. \"CC0-1.0\"".into(),
        ));
    }
    match (asset.kind, &asset.identity) {
        (AssetKind::Head, None) => asset.identity = Some(asset.id.clone()),
        (AssetKind::Head, Some(identity)) if identity.is_empty() => {
            return Err((
                key("identity"),
                "must not be empty: remove it (it defaults to the id) or name the person".into(),
            ));
        }
        (AssetKind::Head, Some(_)) => {}
        (kind, Some(_)) => {
            return Err((
                key("identity"),
                format!("only heads have an identity, this asset is a {kind}: remove the key"),
            ));
        }
        (_, None) => {}
    }
    if let Some(frame) = &asset.frame {
        let finite = frame.translate.iter().all(|v| v.is_finite());
        if !(frame.scale.is_finite() && frame.scale > 0.0 && finite) {
            return Err((
                key("frame"),
                format!(
                    "scale {} must be a positive finite number and translate {:?} finite: \
                     canonical = scale * file + translate",
                    frame.scale, frame.translate
                ),
            ));
        }
    }
    if let Some(landmarks) = &asset.landmarks {
        if asset.kind != AssetKind::Head {
            return Err((
                key("landmarks"),
                format!(
                    "only heads have landmarks, this asset is a {}: remove the key",
                    asset.kind
                ),
            ));
        }
        if let Some(unknown) = landmarks
            .keys()
            .find(|k| !LANDMARK_NAMES.contains(&k.as_str()))
        {
            return Err((
                key("landmarks"),
                format!(
                    "unknown landmark `{unknown}`: give exactly {}",
                    LANDMARK_NAMES.join(", ")
                ),
            ));
        }
        if let Some(missing) = LANDMARK_NAMES.iter().find(|n| !landmarks.contains_key(**n)) {
            return Err((
                key("landmarks"),
                format!(
                    "`{missing}` is missing: give all of {}",
                    LANDMARK_NAMES.join(", ")
                ),
            ));
        }
        if landmarks.values().flatten().any(|v| !v.is_finite()) {
            return Err((key("landmarks"), "every coordinate must be finite".into()));
        }
    }
    Ok(())
}
