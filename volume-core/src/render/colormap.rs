//! Colormaps for colouring a surface by a second field: small tables of control points,
//! interpolated linearly in RGB.
//!
//! - viridis and magma: every 16th entry (and the last) of the 256-entry tables of
//!   matplotlib's `_cm_listed.py` by Nathaniel J. Smith, Stefan van der Walt and Eric Firing,
//!   released under CC0 (<https://github.com/BIDS/colormap>, `colormaps.py`). Entry `i` of
//!   a table sits at `i / 255`.
//! - coolwarm: the 33-point 8-bit RGB table Kenneth Moreland published with "Diverging
//!   Color Maps for Scientific Visualization" (ISVC 2009), evenly spaced (the map ParaView
//!   calls "Cool to Warm").
//! - grey: black to white.
//!
//! The values are display RGB in `[0, 1]`; the renderer writes surface colours without a
//! transfer curve, so a colormapped surface under full light shows the published colours.

use serde::{Deserialize, Serialize};

/// A colormap by name.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Colormap {
    /// Perceptually uniform, dark blue to yellow (matplotlib's default).
    #[default]
    Viridis,
    /// Perceptually uniform, black through purple to light yellow.
    Magma,
    /// Diverging blue–grey–red (Moreland), for data with a meaningful middle.
    Coolwarm,
    /// Black to white.
    #[serde(alias = "gray")]
    Grey,
}

/// viridis at `i / 255` (see the module docs for the source).
#[allow(clippy::unreadable_literal)] // the published values, digit for digit
const VIRIDIS: [(u8, [f32; 3]); 17] = [
    (0, [0.267004, 0.004874, 0.329415]),
    (16, [0.282327, 0.094955, 0.417331]),
    (32, [0.278826, 0.175490, 0.483397]),
    (48, [0.258965, 0.251537, 0.524736]),
    (64, [0.229739, 0.322361, 0.545706]),
    (80, [0.199430, 0.387607, 0.554642]),
    (96, [0.172719, 0.448791, 0.557885]),
    (112, [0.149039, 0.508051, 0.557250]),
    (128, [0.127568, 0.566949, 0.550556]),
    (144, [0.120638, 0.625828, 0.533488]),
    (160, [0.157851, 0.683765, 0.501686]),
    (176, [0.246070, 0.738910, 0.452024]),
    (192, [0.369214, 0.788888, 0.382914]),
    (208, [0.515992, 0.831158, 0.294279]),
    (224, [0.678489, 0.863742, 0.189503]),
    (240, [0.845561, 0.887322, 0.099702]),
    (255, [0.993248, 0.906157, 0.143936]),
];

/// magma at `i / 255` (see the module docs for the source).
#[allow(clippy::unreadable_literal)] // the published values, digit for digit
const MAGMA: [(u8, [f32; 3]); 17] = [
    (0, [0.001462, 0.000466, 0.013866]),
    (16, [0.039608, 0.031090, 0.133515]),
    (32, [0.113094, 0.065492, 0.276784]),
    (48, [0.211718, 0.061992, 0.418647]),
    (64, [0.316654, 0.071690, 0.485380]),
    (80, [0.414709, 0.110431, 0.504662]),
    (96, [0.512831, 0.148179, 0.507648]),
    (112, [0.613617, 0.181811, 0.498536]),
    (128, [0.716387, 0.214982, 0.475290]),
    (144, [0.816914, 0.255895, 0.436461]),
    (160, [0.904281, 0.319610, 0.388137]),
    (176, [0.960949, 0.418323, 0.359630]),
    (192, [0.986700, 0.535582, 0.382210]),
    (208, [0.996096, 0.653659, 0.446213]),
    (224, [0.996898, 0.769591, 0.534892]),
    (240, [0.992440, 0.884330, 0.640099]),
    (255, [0.987053, 0.991438, 0.749504]),
];

/// Moreland's cool–warm table, 33 evenly spaced 8-bit RGB points (module docs).
const COOLWARM: [[u8; 3]; 33] = [
    [59, 76, 192],
    [68, 90, 204],
    [77, 104, 215],
    [87, 117, 225],
    [98, 130, 234],
    [108, 142, 241],
    [119, 154, 247],
    [130, 165, 251],
    [141, 176, 254],
    [152, 185, 255],
    [163, 194, 255],
    [174, 201, 253],
    [184, 208, 249],
    [194, 213, 244],
    [204, 217, 238],
    [213, 219, 230],
    [221, 221, 221],
    [229, 216, 209],
    [236, 211, 197],
    [241, 204, 185],
    [245, 196, 173],
    [247, 187, 160],
    [247, 177, 148],
    [247, 166, 135],
    [244, 154, 123],
    [241, 141, 111],
    [236, 127, 99],
    [229, 112, 88],
    [222, 96, 77],
    [213, 80, 66],
    [203, 62, 56],
    [192, 40, 47],
    [180, 4, 38],
];

fn lerp3(a: [f32; 3], b: [f32; 3], f: f32) -> [f32; 3] {
    [0, 1, 2].map(|c| a[c] + (b[c] - a[c]) * f)
}

impl Colormap {
    pub const ALL: [Colormap; 4] = [
        Colormap::Viridis,
        Colormap::Magma,
        Colormap::Coolwarm,
        Colormap::Grey,
    ];

    /// The name used on the command line, in Python and in session files.
    pub const fn name(self) -> &'static str {
        match self {
            Colormap::Viridis => "viridis",
            Colormap::Magma => "magma",
            Colormap::Coolwarm => "coolwarm",
            Colormap::Grey => "grey",
        }
    }

    /// Parses [`Colormap::name`] (case-insensitive; `gray` is `grey`).
    pub fn from_name(name: &str) -> Option<Self> {
        let name = name.trim().to_ascii_lowercase();
        if name == "gray" {
            return Some(Colormap::Grey);
        }
        Self::ALL.into_iter().find(|c| c.name() == name)
    }

    /// The colour at `t` in `[0, 1]` (clamped; NaN reads as 0).
    pub fn at(self, t: f32) -> [f32; 3] {
        let t = if t.is_nan() { 0.0 } else { t.clamp(0.0, 1.0) };
        match self {
            Colormap::Grey => [t; 3],
            Colormap::Viridis => indexed(&VIRIDIS, t),
            Colormap::Magma => indexed(&MAGMA, t),
            Colormap::Coolwarm => {
                let x = t * (COOLWARM.len() - 1) as f32;
                let i = (x.floor() as usize).min(COOLWARM.len() - 2);
                let rgb = |k: usize| COOLWARM[k].map(|c| f32::from(c) / 255.0);
                lerp3(rgb(i), rgb(i + 1), x - i as f32)
            }
        }
    }

    /// The colour of `value` in `range = [min, max]`: values outside are clamped to the
    /// ends; a range of zero width gives the middle colour.
    pub fn map(self, value: f32, range: [f32; 2]) -> [f32; 3] {
        self.at(normalized(value, range))
    }
}

/// `value`'s position in `[min, max]`, clamped to `[0, 1]` (0.5 for a zero-width range).
pub fn normalized(value: f32, [lo, hi]: [f32; 2]) -> f32 {
    if hi > lo {
        ((value - lo) / (hi - lo)).clamp(0.0, 1.0)
    } else {
        0.5
    }
}

/// Linear interpolation in a table of control points at `index / 255`.
fn indexed(table: &[(u8, [f32; 3])], t: f32) -> [f32; 3] {
    let x = t * 255.0;
    // The first control point at or past `x` (the table starts at 0 and ends at 255).
    let j = table
        .iter()
        .position(|&(i, _)| f32::from(i) >= x)
        .unwrap_or(table.len() - 1)
        .max(1);
    let (i0, c0) = table[j - 1];
    let (i1, c1) = table[j];
    let f = (x - f32::from(i0)) / (f32::from(i1) - f32::from(i0));
    lerp3(c0, c1, f.clamp(0.0, 1.0))
}

impl std::fmt::Display for Colormap {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: [f32; 3], b: [f32; 3]) -> bool {
        a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-6)
    }

    #[test]
    fn control_points_are_reproduced_and_ends_clamp() {
        assert!(close(Colormap::Viridis.at(0.0), VIRIDIS[0].1));
        assert!(close(Colormap::Viridis.at(1.0), VIRIDIS[16].1));
        assert!(close(Colormap::Viridis.at(128.0 / 255.0), VIRIDIS[8].1));
        assert!(close(Colormap::Magma.at(240.0 / 255.0), MAGMA[15].1));
        // Moreland's midpoint is the grey (221, 221, 221).
        assert!(close(Colormap::Coolwarm.at(0.5), [221.0 / 255.0; 3]));
        assert!(close(
            Colormap::Coolwarm.at(1.0),
            [180.0 / 255.0, 4.0 / 255.0, 38.0 / 255.0]
        ));
        assert!(close(Colormap::Grey.at(0.25), [0.25; 3]));
        for c in Colormap::ALL {
            assert_eq!(c.at(-3.0), c.at(0.0));
            assert_eq!(c.at(7.0), c.at(1.0));
            assert_eq!(c.at(f32::NAN), c.at(0.0));
            assert_eq!(Colormap::from_name(c.name()), Some(c));
        }
        assert_eq!(Colormap::from_name("Gray"), Some(Colormap::Grey));
        assert_eq!(Colormap::from_name("jet"), None);
    }

    #[test]
    fn between_control_points_the_colour_is_their_linear_blend() {
        // Halfway between viridis entries 16 and 32 (t = 24/255).
        let want = lerp3(VIRIDIS[1].1, VIRIDIS[2].1, 0.5);
        assert!(close(Colormap::Viridis.at(24.0 / 255.0), want));
        // Between the last two entries (240 and 255, 15 apart).
        let want = lerp3(MAGMA[15].1, MAGMA[16].1, 5.0 / 15.0);
        assert!(close(Colormap::Magma.at(245.0 / 255.0), want));
        // A quarter of the way from coolwarm point 3 to 4.
        let t = (3.0 + 0.25) / 32.0;
        let rgb = |k: usize| COOLWARM[k].map(|c| f32::from(c) / 255.0);
        assert!(close(Colormap::Coolwarm.at(t), lerp3(rgb(3), rgb(4), 0.25)));
        // Map: a value to its position in the range, clamped outside.
        assert_eq!(normalized(3.0, [2.0, 6.0]), 0.25);
        assert_eq!(normalized(-9.0, [2.0, 6.0]), 0.0);
        assert_eq!(normalized(1.0, [2.0, 2.0]), 0.5);
        assert_eq!(Colormap::Grey.map(5.0, [2.0, 6.0]), [0.75; 3]);
    }

    #[test]
    fn names_serialize_in_lowercase() {
        let json = serde_json::to_string(&Colormap::Coolwarm).unwrap();
        assert_eq!(json, "\"coolwarm\"");
        let grey: Colormap = serde_json::from_str("\"gray\"").unwrap();
        assert_eq!(grey, Colormap::Grey);
    }
}
