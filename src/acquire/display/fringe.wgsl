// One fringe pattern, drawn per screen pixel: the GPU twin of
// `levels::reference_frame` (see levels.rs for the gamma and dither
// conventions and patterns.rs for the one definition of a pattern).

struct Fringe {
    // Phase in cycles at screen point (u, v): a·u + b·v + c, i.e.
    // τ·s(u, v) + φ/2π with c reduced modulo 1 on the CPU in f64.
    a: f32,
    b: f32,
    c: f32,
    // 2/γ: g^(1/γ) = |cos(π x)|^(2/γ) with x the phase in cycles.
    two_over_gamma: f32,
    // 0: round to nearest (threshold ½); 1: 8×8 Bayer thresholds.
    dither: u32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
}

@group(0) @binding(0) var<uniform> fringe: Fringe;

const PI: f32 = 3.14159265358979;

// One triangle covering the whole target: (-1,-1), (3,-1), (-1,3).
@vertex
fn vs_main(@builtin(vertex_index) i: u32) -> @builtin(position) vec4<f32> {
    let x = f32((i << 1u) & 2u) * 2.0 - 1.0;
    let y = f32(i & 2u) * 2.0 - 1.0;
    return vec4<f32>(x, y, 0.0, 1.0);
}

// Bits of col ⊕ row and row interleaved, finest bits most significant
// (levels::bayer8).
fn bayer8(col: u32, row: u32) -> u32 {
    let x = col & 7u;
    let y = row & 7u;
    let xy = x ^ y;
    var b = 0u;
    for (var k = 0u; k < 3u; k++) {
        b |= ((xy >> k) & 1u) << (2u * (2u - k) + 1u);
        b |= ((y >> k) & 1u) << (2u * (2u - k));
    }
    return b;
}

@fragment
fn fs_main(@builtin(position) pos: vec4<f32>) -> @location(0) vec4<f32> {
    // pos.xy is the pixel centre (c + ½, r + ½): the spec's (u, v).
    let cycles = fract(fringe.a * pos.x + (fringe.b * pos.y + fringe.c));
    // g = ½ + ½ cos(2π x) = cos²(π x): no cancellation near g = 0, where
    // g^(1/γ) is steep.
    let h = abs(cos(PI * cycles));
    var ideal = 0.0;
    if (h > 0.0) {
        ideal = 255.0 * pow(h, fringe.two_over_gamma);
    }
    let p = vec2<u32>(pos.xy);
    var t = 0.5;
    if (fringe.dither == 1u) {
        t = (f32(bayer8(p.x, p.y)) + 0.5) / 64.0;
    }
    let level = min(floor(ideal + t), 255.0);
    let y = level / 255.0;
    return vec4<f32>(y, y, y, 1.0);
}
