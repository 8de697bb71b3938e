//! Writing small glTF files with given materials, for the material tests.
#![allow(dead_code)]

use std::path::{Path, PathBuf};

use lightfarm_render::scene::Scene;
use serde_json::{json, Value};

pub fn scratch_dir(name: &str) -> PathBuf {
    let dir =
        std::env::temp_dir().join(format!("lightfarm-materials-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("create temp dir");
    dir
}

/// One triangle's positions and indices, 48 bytes.
pub fn triangle_bin() -> Vec<u8> {
    [0.0f32, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0]
        .iter()
        .flat_map(|f| f.to_le_bytes())
        .chain([0u32, 1, 2].iter().flat_map(|i| i.to_le_bytes()))
        .collect()
}

/// A glTF document with one mesh holding one triangle primitive per material of `materials`;
/// `buffer_uri` None is the GLB's binary chunk.
pub fn document(materials: &[Value], buffer_uri: Option<&str>) -> Value {
    let primitives: Vec<Value> = (0..materials.len())
        .map(|i| json!({"attributes": {"POSITION": 0}, "indices": 1, "material": i}))
        .collect();
    let mut buffer = json!({"byteLength": 48});
    if let Some(uri) = buffer_uri {
        buffer["uri"] = json!(uri);
    }
    json!({
        "asset": {"version": "2.0"},
        "extensionsUsed": ["KHR_materials_ior", "KHR_materials_specular"],
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0}],
        "meshes": [{"primitives": primitives}],
        "materials": materials,
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3",
             "min": [0, 0, 0], "max": [1, 1, 0]},
            {"bufferView": 1, "componentType": 5125, "count": 3, "type": "SCALAR"}
        ],
        "bufferViews": [
            {"buffer": 0, "byteOffset": 0, "byteLength": 36},
            {"buffer": 0, "byteOffset": 36, "byteLength": 12}
        ],
        "buffers": [buffer],
    })
}

/// Writes `<dir>/<stem>.gltf` (with its .bin) holding `materials`.
pub fn write_gltf(dir: &Path, stem: &str, materials: &[Value]) -> PathBuf {
    let bin = format!("{stem}.bin");
    std::fs::write(dir.join(&bin), triangle_bin()).expect("write bin");
    let path = dir.join(format!("{stem}.gltf"));
    let text = serde_json::to_string_pretty(&document(materials, Some(&bin))).expect("json");
    std::fs::write(&path, text).expect("write gltf");
    path
}

/// Writes `<dir>/<stem>.glb` holding `materials`.
pub fn write_glb_file(dir: &Path, stem: &str, materials: &[Value]) -> PathBuf {
    let mut json = serde_json::to_vec(&document(materials, None)).expect("json");
    while !json.len().is_multiple_of(4) {
        json.push(b' ');
    }
    let bin = triangle_bin();
    let total = 12 + 8 + json.len() + 8 + bin.len();
    let mut glb = Vec::with_capacity(total);
    glb.extend_from_slice(b"glTF");
    glb.extend_from_slice(&2u32.to_le_bytes());
    glb.extend_from_slice(&(total as u32).to_le_bytes());
    glb.extend_from_slice(&(json.len() as u32).to_le_bytes());
    glb.extend_from_slice(b"JSON");
    glb.extend_from_slice(&json);
    glb.extend_from_slice(&(bin.len() as u32).to_le_bytes());
    glb.extend_from_slice(b"BIN\0");
    glb.extend_from_slice(&bin);
    let path = dir.join(format!("{stem}.glb"));
    std::fs::write(&path, glb).expect("write glb");
    path
}

/// Writes `<dir>/<stem>.gltf` from `document` with `bin` as `<dir>/<stem>.bin`: the document's
/// buffer 0 is pointed at it (its `uri` and `byteLength` are set here).
pub fn write_gltf_document(dir: &Path, stem: &str, document: &Value, bin: &[u8]) -> PathBuf {
    let bin_name = format!("{stem}.bin");
    std::fs::write(dir.join(&bin_name), bin).expect("write bin");
    let mut document = document.clone();
    document["buffers"] = json!([{"byteLength": bin.len(), "uri": bin_name}]);
    let path = dir.join(format!("{stem}.gltf"));
    let text = serde_json::to_string_pretty(&document).expect("json");
    std::fs::write(&path, text).expect("write gltf");
    path
}

pub fn load(path: &Path) -> Scene {
    Scene::load_gltf(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// A material as an exporter writes it: base colour, metallic-roughness, optional extras.
pub fn gltf_material(name: &str, extras: Option<Value>) -> Value {
    let mut m = json!({
        "name": name,
        "pbrMetallicRoughness": {
            "baseColorFactor": [0.7, 0.5, 0.4, 0.9],
            "metallicFactor": 0.3,
            "roughnessFactor": 0.8
        }
    });
    if let Some(e) = extras {
        m["extras"] = e;
    }
    m
}

pub fn close(a: f32, b: f32) -> bool {
    (a - b).abs() <= 1e-6
}

pub fn close3(a: [f32; 3], b: [f32; 3]) -> bool {
    a.iter().zip(b).all(|(x, y)| close(*x, y))
}
