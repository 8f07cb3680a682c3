//! Colour scales of the views. Fixed, documented scales (not Rerun's automatic colours) so
//! that the summary text can say what a colour means.

/// RGBA colour as Rerun takes it.
pub type Rgba = [u8; 4];

/// Interpolates piecewise linearly between equally spaced colour stops; `t` is clamped to [0, 1].
fn ramp(stops: &[[f32; 3]], t: f64) -> Rgba {
    let t = if t.is_finite() { t.clamp(0.0, 1.0) as f32 } else { 0.0 };
    let x = t * (stops.len() - 1) as f32;
    let i = (x.floor() as usize).min(stops.len() - 2);
    let f = x - i as f32;
    let c = |k: usize| (255.0 * (stops[i][k] * (1.0 - f) + stops[i + 1][k] * f)).round() as u8;
    [c(0), c(1), c(2), 255]
}

/// Sequential scale for magnitudes, legible on the viewer's dark background:
/// 0 blue, 0.25 cyan, 0.5 green, 0.75 yellow, 1 red.
pub fn magnitude(t: f64) -> Rgba {
    ramp(&[[0.25, 0.45, 1.0], [0.1, 0.85, 0.95], [0.25, 0.85, 0.3], [0.98, 0.85, 0.15], [0.95, 0.2, 0.15]], t)
}

/// Diverging scale for signed values in [-1, 1]: -1 blue, 0 light grey, +1 red.
pub fn signed(t: f64) -> Rgba {
    ramp(&[[0.2, 0.45, 1.0], [0.85, 0.85, 0.85], [1.0, 0.25, 0.2]], 0.5 * (t + 1.0))
}

/// A beam that a diagnosis flags (to measure again).
pub const FLAGGED: Rgba = [0xff, 0x30, 0x30, 255];

/// Categorical colour of a station (stable across views: beams, residual series, bars).
pub fn station(s: u32) -> Rgba {
    const P: [Rgba; 8] = [
        [0x4e, 0x9a, 0xf0, 255],
        [0xf5, 0x8b, 0x2f, 255],
        [0x5c, 0xc8, 0x6b, 255],
        [0xe0, 0x5a, 0xc8, 255],
        [0xf0, 0xd8, 0x4a, 255],
        [0x54, 0xd6, 0xd0, 255],
        [0xc8, 0x7a, 0x5a, 255],
        [0xa8, 0x8c, 0xf0, 255],
    ];
    P[s as usize % P.len()]
}

/// The deflector's beam in the live view: yellow when settled, red while moving (neither is a
/// station's colour for the usual three stations).
pub fn deflector(settled: bool) -> Rgba {
    if settled {
        [255, 230, 60, 255]
    } else {
        [255, 80, 80, 255]
    }
}

/// The same colour, lighter and translucent (uncertainty bands).
pub fn faded(c: Rgba) -> Rgba {
    [c[0] / 2 + 64, c[1] / 2 + 64, c[2] / 2 + 64, 170]
}

/// Colour of each function within one plot: red, green, blue for the components X, Y, Z;
/// yellow and magenta for squareness.
pub fn component(i: usize) -> Rgba {
    const C: [Rgba; 5] = [
        [0xf0, 0x5a, 0x4e, 255], // red
        [0x5c, 0xc8, 0x6b, 255], // green
        [0x4e, 0x9a, 0xf0, 255], // blue
        [0xe0, 0xc0, 0x40, 255], // yellow
        [0xe0, 0x5a, 0xc8, 255], // magenta
    ];
    C[i % C.len()]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scales_hit_their_end_stops_and_clamp() {
        assert_eq!(magnitude(0.0), magnitude(-3.0));
        assert_eq!(magnitude(1.0), magnitude(7.0));
        assert_eq!(magnitude(f64::NAN), magnitude(0.0));
        assert_eq!(signed(0.0), [217, 217, 217, 255]);
        assert!(signed(-1.0)[2] > signed(-1.0)[0], "negative is blue");
        assert!(signed(1.0)[0] > signed(1.0)[2], "positive is red");
    }
}
