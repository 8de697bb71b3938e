// Orthonormal frames and small helpers shared by the BSDFs and the integrator.

struct Frame {
    t: vec3<f32>,
    b: vec3<f32>,
    n: vec3<f32>,
};

// Duff et al. 2017, "Building an Orthonormal Basis, Revisited": branch-free and continuous.
fn frame_from_normal(n: vec3<f32>) -> Frame {
    let s = select(-1.0, 1.0, n.z >= 0.0);
    let a = -1.0 / (s + n.z);
    let b = n.x * n.y * a;
    let t = vec3<f32>(1.0 + s * n.x * n.x * a, s * b, -s * n.x);
    let bb = vec3<f32>(b, s + n.y * n.y * a, -n.y);
    return Frame(t, bb, n);
}

// Builds a frame around n whose tangent follows `tangent` as closely as possible (normal mapping).
fn frame_from_normal_tangent(n: vec3<f32>, tangent: vec3<f32>) -> Frame {
    let t0 = tangent - n * dot(n, tangent);
    let len2 = dot(t0, t0);
    if (len2 < 1e-12) {
        return frame_from_normal(n);
    }
    let t = t0 * inverseSqrt(len2);
    return Frame(t, cross(n, t), n);
}

fn to_local(f: Frame, v: vec3<f32>) -> vec3<f32> {
    return vec3<f32>(dot(v, f.t), dot(v, f.b), dot(v, f.n));
}

fn to_world(f: Frame, v: vec3<f32>) -> vec3<f32> {
    return f.t * v.x + f.b * v.y + f.n * v.z;
}

fn luminance(c: vec3<f32>) -> f32 {
    return dot(c, vec3<f32>(0.2126, 0.7152, 0.0722));
}

fn max3(v: vec3<f32>) -> f32 {
    return max(v.x, max(v.y, v.z));
}

fn min3(v: vec3<f32>) -> f32 {
    return min(v.x, min(v.y, v.z));
}

fn power_heuristic(a: f32, b: f32) -> f32 {
    let a2 = a * a;
    let b2 = b * b;
    if (a2 + b2 <= 0.0) {
        return 0.0;
    }
    return a2 / (a2 + b2);
}

fn sample_cosine_hemisphere(u: vec2<f32>) -> vec3<f32> {
    // Concentric disk mapping keeps strata compact (Shirley & Chiu).
    let o = 2.0 * u - vec2<f32>(1.0);
    if (o.x == 0.0 && o.y == 0.0) {
        return vec3<f32>(0.0, 0.0, 1.0);
    }
    var r: f32;
    var theta: f32;
    if (abs(o.x) > abs(o.y)) {
        r = o.x;
        theta = (PI / 4.0) * (o.y / o.x);
    } else {
        r = o.y;
        theta = (PI / 2.0) - (PI / 4.0) * (o.x / o.y);
    }
    let d = r * vec2<f32>(cos(theta), sin(theta));
    let z = sqrt(max(0.0, 1.0 - dot(d, d)));
    return vec3<f32>(d.x, d.y, z);
}
