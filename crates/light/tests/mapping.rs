//! The lat-long convention and the per-sample rotation/flip.

use lightfarm_light::{dir_to_uv, uv_to_dir, EnvTransform, Hdri};

const TOL: f32 = 1e-5;

fn close3(a: [f32; 3], b: [f32; 3]) -> bool {
    a.iter().zip(b).all(|(x, y)| (x - y).abs() < TOL)
}

/// Distance on the u circle, so 0.999999 and 0 count as close.
fn u_dist(a: f32, b: f32) -> f32 {
    let d = (a - b).abs();
    d.min(1.0 - d)
}

#[test]
fn convention_points() {
    let cases = [
        ([0.0, 0.0, -1.0], [0.0, 0.5]),
        ([1.0, 0.0, 0.0], [0.25, 0.5]),
        ([0.0, 0.0, 1.0], [0.5, 0.5]),
        ([-1.0, 0.0, 0.0], [0.75, 0.5]),
    ];
    for (d, uv) in cases {
        let got = dir_to_uv(d);
        assert!(
            u_dist(got[0], uv[0]) < TOL && (got[1] - uv[1]).abs() < TOL,
            "{d:?} -> {got:?}"
        );
        assert!(close3(uv_to_dir(uv), d), "{uv:?} -> {:?}", uv_to_dir(uv));
    }
    assert!(dir_to_uv([0.0, 1.0, 0.0])[1].abs() < TOL, "+Y is v = 0");
    assert!(
        (dir_to_uv([0.0, -1.0, 0.0])[1] - 1.0).abs() < TOL,
        "-Y is v = 1"
    );
    assert!(close3(uv_to_dir([0.3, 0.0]), [0.0, 1.0, 0.0]));
}

#[test]
fn uv_dir_round_trip() {
    for iu in 0..64 {
        for iv in 1..32 {
            let uv = [(iu as f32 + 0.5) / 64.0, (iv as f32) / 32.0];
            let d = uv_to_dir(uv);
            let len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
            assert!((len - 1.0).abs() < TOL);
            let back = dir_to_uv(d);
            assert!(u_dist(back[0], uv[0]) < 1e-4, "{uv:?} -> {back:?}");
            assert!((back[1] - uv[1]).abs() < 1e-4, "{uv:?} -> {back:?}");
            assert!(close3(uv_to_dir(back), d));
        }
    }
}

#[test]
fn transform_round_trip() {
    let dirs = [
        [0.3, -0.4, 0.866],
        [0.0, 1.0, 0.0],
        [-0.7, 0.1, -0.7],
        [1.0, 0.0, 0.0],
    ];
    for rotation_deg in [0.0, 17.5, 90.0, -135.0, 359.0] {
        for flip in [false, true] {
            let t = EnvTransform { rotation_deg, flip };
            for d in dirs {
                assert!(close3(t.env_to_world(t.world_to_env(d)), d), "{t:?} {d:?}");
                assert!(close3(t.world_to_env(t.env_to_world(d)), d), "{t:?} {d:?}");
            }
        }
    }
}

#[test]
fn rotation_by_90_degrees() {
    let t = EnvTransform {
        rotation_deg: 90.0,
        flip: false,
    };
    // R_y(-90°): x' = -z, z' = x.
    assert!(close3(t.world_to_env([1.0, 0.0, 0.0]), [0.0, 0.0, 1.0]));
    assert!(close3(t.world_to_env([0.0, 0.0, -1.0]), [1.0, 0.0, 0.0]));
    assert!(close3(t.world_to_env([0.0, 1.0, 0.0]), [0.0, 1.0, 0.0]));
    // So world -Z (u = 0 unrotated) now sees env u = 0.25: the map turns by a quarter.
    for u in [0.0f32, 0.1, 0.6, 0.9] {
        let world = uv_to_dir([u, 0.4]);
        let env_uv = dir_to_uv(t.world_to_env(world));
        assert!(
            u_dist(env_uv[0], (u + 0.25) % 1.0) < 1e-4,
            "{u} -> {env_uv:?}"
        );
        assert!((env_uv[1] - 0.4).abs() < 1e-4);
    }
}

#[test]
fn flip_mirrors_u() {
    let t = EnvTransform {
        rotation_deg: 0.0,
        flip: true,
    };
    for u in [0.05f32, 0.25, 0.4, 0.5, 0.8] {
        let env_uv = dir_to_uv(t.world_to_env(uv_to_dir([u, 0.3])));
        assert!(u_dist(env_uv[0], 1.0 - u) < 1e-4, "{u} -> {env_uv:?}");
        assert!((env_uv[1] - 0.3).abs() < 1e-4);
    }
}

#[test]
fn lookup_finds_the_texel_in_a_direction() {
    let (w, h) = (8u32, 4u32);
    let texels = (0..w * h).map(|i| [i as f32, 0.0, 0.0]).collect();
    let hdri = Hdri::from_texels(w, h, texels).expect("valid map");
    // +X is u = 0.25 -> column 2; the equator row boundary v = 0.5 falls into row 2.
    assert_eq!(hdri.lookup([1.0, 0.0, 0.0])[0], (2 * w + 2) as f32);
    assert!(
        hdri.lookup([0.0, 1.0, 0.0])[0] < w as f32,
        "+Y is in the top row"
    );
    let d = uv_to_dir([0.7, 0.9]);
    assert_eq!(hdri.lookup(d)[0], (3 * w + 5) as f32);
    assert_eq!(
        Hdri::constant(4, 2, [2.0; 3]).lookup([0.0, 0.0, 1.0]),
        [2.0; 3]
    );
}
