//! Checks of spec values shared by the spec's sections; each error names the dotted key and
//! says the accepted range.

use crate::error::SceneError;

/// Non-negative finite weights with a positive sum.
pub(crate) fn weights(
    key: &str,
    w: &[f64],
    bad: &dyn Fn(&str, String) -> SceneError,
) -> Result<(), SceneError> {
    if w.iter().all(|x| x.is_finite() && *x >= 0.0) && w.iter().sum::<f64>() > 0.0 {
        Ok(())
    } else {
        Err(bad(
            key,
            format!("is {w:?}; give non-negative weights with a positive sum"),
        ))
    }
}

pub(crate) fn int_in(
    key: &str,
    value: i64,
    min: i64,
    max: i64,
    bad: &dyn Fn(&str, String) -> SceneError,
) -> Result<u64, SceneError> {
    if value < min || value > max {
        return Err(bad(
            key,
            format!("is {value}; it must be an integer in {min}..={max}"),
        ));
    }
    // min >= 1 for every caller, so the value is positive here.
    u64::try_from(value).map_err(|_| bad(key, format!("is {value}; it must be positive")))
}

pub(crate) fn probability(
    key: &str,
    p: f64,
    bad: &dyn Fn(&str, String) -> SceneError,
) -> Result<(), SceneError> {
    if (0.0..=1.0).contains(&p) {
        Ok(())
    } else {
        Err(bad(key, format!("is {p}; it must be in [0, 1]")))
    }
}

pub(crate) fn positive(
    key: &str,
    v: f64,
    bad: &dyn Fn(&str, String) -> SceneError,
) -> Result<(), SceneError> {
    if v.is_finite() && v > 0.0 {
        Ok(())
    } else {
        Err(bad(key, format!("is {v}; it must be a finite number > 0")))
    }
}

/// A `[min, max]` range: finite, ordered, inside `[lo, hi]`.
pub(crate) fn range_in(
    key: &str,
    [min, max]: [f64; 2],
    lo: f64,
    hi: f64,
    bad: &dyn Fn(&str, String) -> SceneError,
) -> Result<(), SceneError> {
    if !(min.is_finite() && max.is_finite()) {
        return Err(bad(
            key,
            format!("is [{min}, {max}]; both ends must be finite numbers"),
        ));
    }
    if min > max {
        return Err(bad(
            key,
            format!("is [{min}, {max}]: min > max; write it as [{max}, {min}]"),
        ));
    }
    if min < lo || max > hi {
        return Err(bad(
            key,
            format!("is [{min}, {max}]; it must lie within [{lo}, {hi}] (clamp it to that range)"),
        ));
    }
    Ok(())
}
