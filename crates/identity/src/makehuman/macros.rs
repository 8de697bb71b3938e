//! MakeHuman's macro modifiers: gender × age × muscle × weight × ethnicity as weights of the
//! `macrodetails` targets.
//!
//! The rule is MakeHuman 1.x's (`apps/humanmodifier.py` MacroModifier, described in the
//! MakeHuman manual "Macro modifiers"): each macro value is split piecewise-linearly between the
//! two named anchor targets around it, and a target combining several macros weighs the product
//! of their parts. The ethnic targets (`african-female-young`) combine gender × age ×
//! ethnicity, the universal ones (`universal-female-young-averagemuscle-averageweight`) gender
//! × age × muscle × weight.

use std::collections::BTreeMap;

/// Macro values on MakeHuman's slider scale, each in [0, 1].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Macros {
    /// 0 female, 1 male.
    pub gender: f64,
    /// MakeHuman's age slider: 0 = 1 year, 0.1875 = 11, 0.5 = 25, 1 = 90 ([`age_slider`]).
    pub age: f64,
    /// 0.5 average.
    pub muscle: f64,
    /// 0.5 average.
    pub weight: f64,
    /// African, Asian, Caucasian shares (normalised here; all zero means equal shares).
    pub ethnicity: [f64; 3],
}

/// MakeHuman's age slider for an age in years (`human.py` setAgeYears: 1, 11, 25 and 90 years
/// at 0, 0.1875, 0.5 and 1, linear between).
pub fn age_slider(years: f64) -> f64 {
    let y = years.clamp(1.0, 90.0);
    if y < 11.0 {
        (y - 1.0) / 10.0 * 0.1875
    } else if y < 25.0 {
        0.1875 + (y - 11.0) / 14.0 * (0.5 - 0.1875)
    } else {
        0.5 + (y - 25.0) / 65.0 * 0.5
    }
}

/// The two anchors around `v` on `knots` and their weights.
fn split<'a>(v: f64, knots: &[(f64, &'a str)]) -> Vec<(&'a str, f64)> {
    let v = v.clamp(knots[0].0, knots[knots.len() - 1].0);
    for pair in knots.windows(2) {
        let ((lo, a), (hi, b)) = (pair[0], pair[1]);
        if v <= hi {
            let t = (v - lo) / (hi - lo);
            return vec![(a, 1.0 - t), (b, t)];
        }
    }
    vec![(knots[knots.len() - 1].1, 1.0)]
}

/// Weights of the `macrodetails/*` targets for `m`, keyed by target name; weights below 1e-6
/// are dropped.
pub fn macro_weights(m: &Macros) -> BTreeMap<String, f64> {
    let gender = [
        ("female", 1.0 - m.gender.clamp(0.0, 1.0)),
        ("male", m.gender.clamp(0.0, 1.0)),
    ];
    let age = split(
        m.age,
        &[
            (0.0, "baby"),
            (0.1875, "child"),
            (0.5, "young"),
            (1.0, "old"),
        ],
    );
    let muscle = split(
        m.muscle,
        &[
            (0.0, "minmuscle"),
            (0.5, "averagemuscle"),
            (1.0, "maxmuscle"),
        ],
    );
    let weight = split(
        m.weight,
        &[
            (0.0, "minweight"),
            (0.5, "averageweight"),
            (1.0, "maxweight"),
        ],
    );
    let e = m.ethnicity.map(|x| x.max(0.0));
    let sum: f64 = e.iter().sum();
    let e = if sum > 0.0 {
        e.map(|x| x / sum)
    } else {
        [1.0 / 3.0; 3]
    };
    let races = [("african", e[0]), ("asian", e[1]), ("caucasian", e[2])];

    let mut out = BTreeMap::new();
    let mut add = |name: String, w: f64| {
        if w > 1e-6 {
            *out.entry(format!("macrodetails/{name}")).or_insert(0.0) += w;
        }
    };
    for (g, gw) in gender {
        for &(a, aw) in &age {
            for (r, rw) in races {
                add(format!("{r}-{g}-{a}"), gw * aw * rw);
            }
            for &(mu, mw) in &muscle {
                for &(we, ww) in &weight {
                    add(format!("universal-{g}-{a}-{mu}-{we}"), gw * aw * mw * ww);
                }
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn weights_partition_unity() {
        let m = Macros {
            gender: 0.3,
            age: 0.7,
            muscle: 0.2,
            weight: 0.9,
            ethnicity: [1.0, 2.0, 1.0],
        };
        let w = macro_weights(&m);
        let ethnic: f64 = w
            .iter()
            .filter(|(k, _)| !k.contains("universal"))
            .map(|(_, v)| v)
            .sum();
        let universal: f64 = w
            .iter()
            .filter(|(k, _)| k.contains("universal"))
            .map(|(_, v)| v)
            .sum();
        assert!((ethnic - 1.0).abs() < 1e-12 && (universal - 1.0).abs() < 1e-12);
        assert!((w["macrodetails/asian-female-young"] - 0.7 * 0.6 * 0.5).abs() < 1e-12);
    }

    #[test]
    fn age_years_match_makehuman_anchors() {
        for (y, s) in [(1.0, 0.0), (11.0, 0.1875), (25.0, 0.5), (90.0, 1.0)] {
            assert!((age_slider(y) - s).abs() < 1e-12, "{y} years");
        }
    }
}
