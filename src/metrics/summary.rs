//! Aggregation of per-pair metrics into the mean ± std rows of the paper's tables, with counts of what was excluded.

use serde::{Deserialize, Serialize};

/// Mean and population standard deviation (ddof = 0, as numpy's default) of the finite values of a metric, with the
/// number of values used and excluded (`None`: excluded by a symmetry or undefined; non-finite, e.g. an infinite
/// PSNR of identical images).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct MeanStd {
    /// Mean of the used values (NaN when none; serialised as null, read back as NaN).
    #[serde(deserialize_with = "nan_if_null")]
    pub mean: f64,
    /// Population standard deviation of the used values.
    #[serde(deserialize_with = "nan_if_null")]
    pub std: f64,
    /// Number of values used.
    pub n: usize,
    /// Number of values excluded (undefined or non-finite).
    pub excluded: usize,
    /// Median of the used values (NaN when none): a few ambiguous pairs (a contact hidden in the sensor noise) can
    /// dominate a mean.
    #[serde(default, deserialize_with = "nan_if_null")]
    pub median: f64,
}

/// serde_json writes a NaN as null; read null back as NaN.
fn nan_if_null<'de, D: serde::Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
    Ok(Option::<f64>::deserialize(d)?.unwrap_or(f64::NAN))
}

/// An `f64` in JSON that keeps infinities: finite values as numbers, ±∞ as the strings `"inf"` / `"-inf"` (JSON has
/// no number for them; serde_json would write null and then refuse to read it as an `f64`), NaN as null. Reads
/// numbers, those strings, `"nan"`, and null (as NaN). For `#[serde(with = "…")]`.
pub mod json_f64 {
    use serde::{Deserialize, Deserializer, Serializer};

    /// Write `v` (see the module docs).
    pub fn serialize<S: Serializer>(v: &f64, s: S) -> Result<S::Ok, S::Error> {
        if v.is_finite() {
            s.serialize_f64(*v)
        } else if v.is_nan() {
            s.serialize_none()
        } else if *v > 0.0 {
            s.serialize_str("inf")
        } else {
            s.serialize_str("-inf")
        }
    }

    /// Read a value written by [`serialize`] (or a plain number or null).
    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
        #[derive(Deserialize)]
        #[serde(untagged)]
        enum Repr {
            Number(f64),
            Text(String),
            Null(()),
        }
        match Option::<Repr>::deserialize(d)? {
            Some(Repr::Number(v)) => Ok(v),
            None | Some(Repr::Null(())) => Ok(f64::NAN),
            Some(Repr::Text(t)) => match t.as_str() {
                "inf" | "+inf" | "Infinity" => Ok(f64::INFINITY),
                "-inf" | "-Infinity" => Ok(f64::NEG_INFINITY),
                "nan" | "NaN" => Ok(f64::NAN),
                other => Err(serde::de::Error::custom(format!(
                    "'{other}' is not a number (a number, \"inf\", \"-inf\" or null)"
                ))),
            },
        }
    }
}

impl MeanStd {
    /// Aggregate `values` (see the type docs).
    pub fn of(values: impl IntoIterator<Item = Option<f64>>) -> Self {
        let mut used = Vec::new();
        let mut excluded = 0;
        for v in values {
            match v {
                Some(x) if x.is_finite() => used.push(x),
                _ => excluded += 1,
            }
        }
        if used.is_empty() {
            return Self {
                mean: f64::NAN,
                std: f64::NAN,
                n: 0,
                excluded,
                median: f64::NAN,
            };
        }
        let n = used.len() as f64;
        let mean = used.iter().sum::<f64>() / n;
        let var = used.iter().map(|x| (x - mean) * (x - mean)).sum::<f64>() / n;
        used.sort_by(f64::total_cmp);
        let k = used.len() / 2;
        let median = if used.len() % 2 == 1 {
            used[k]
        } else {
            0.5 * (used[k - 1] + used[k])
        };
        Self {
            mean,
            std: var.sqrt(),
            n: used.len(),
            excluded,
            median,
        }
    }
}

/// Named [`MeanStd`] rows, in insertion order.
pub type Summary = Vec<(String, MeanStd)>;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mean_std_excludes_undefined_values() {
        let m = MeanStd::of([Some(1.0), Some(3.0), None, Some(f64::INFINITY)]);
        assert_eq!((m.mean, m.std, m.n, m.excluded), (2.0, 1.0, 2, 2));
        assert_eq!(m.median, 2.0);
        assert!(MeanStd::of([None]).mean.is_nan());
        assert!(MeanStd::of([None]).median.is_nan());
    }

    #[test]
    fn json_round_trip_keeps_values_and_turns_null_back_into_nan() {
        let m = MeanStd::of([Some(1.0), Some(3.0), None]);
        let back: MeanStd = serde_json::from_str(&serde_json::to_string(&m).unwrap()).unwrap();
        assert_eq!(back, m);
        let none = MeanStd::of([None]);
        let json = serde_json::to_string(&none).unwrap();
        assert!(json.contains("\"mean\":null"), "{json}");
        let back: MeanStd = serde_json::from_str(&json).unwrap();
        assert!(back.mean.is_nan() && back.std.is_nan() && back.median.is_nan());
        assert_eq!((back.n, back.excluded), (0, 1));
    }

    #[test]
    fn median_of_odd_and_even_counts_ignores_an_outlier() {
        let odd = MeanStd::of([Some(9.0), Some(0.5), Some(100.0), Some(1.0), Some(0.1)]);
        assert_eq!(odd.median, 1.0);
        let even = MeanStd::of([Some(4.0), Some(1.0), Some(2.0), Some(1000.0)]);
        assert_eq!(even.median, 3.0);
    }
}
