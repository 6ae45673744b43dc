//! Settings of resumable jobs (`tnd eval --records`, `tnd recording track`): a job writes the settings its results
//! depend on beside them, and a rerun into the same output resumes only under the same settings. This module says
//! which settings differ, so that the refusal can name them.

use serde_json::Value;

/// The settings where `now` and `then` differ, as `name: then -> now` (`derender.samples: 2 -> 3`); nested objects
/// are named by dotted paths, a setting missing from `then` shows as `null`.
pub fn setting_differences(now: &Value, then: &Value) -> Vec<String> {
    let mut out = Vec::new();
    differences("", now, then, &mut out);
    out
}

fn differences(prefix: &str, now: &Value, then: &Value, out: &mut Vec<String>) {
    match (now, then) {
        (Value::Object(a), Value::Object(b)) => {
            for (k, v) in a {
                let name = if prefix.is_empty() {
                    k.clone()
                } else {
                    format!("{prefix}.{k}")
                };
                differences(&name, v, b.get(k).unwrap_or(&Value::Null), out);
            }
        }
        (a, b) if a != b => out.push(format!("{prefix}: {b} -> {a}")),
        _ => {}
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    #[test]
    fn names_each_differing_setting_by_its_path() {
        let then = json!({"seed": 0, "sampler": {"steps": 25, "eta": 0.0}, "model": "a"});
        let now =
            json!({"seed": 1, "sampler": {"steps": 25, "eta": 0.5}, "model": "a", "new": true});
        let mut named = setting_differences(&now, &then);
        named.sort();
        assert_eq!(
            named,
            [
                "new: null -> true",
                "sampler.eta: 0.0 -> 0.5",
                "seed: 0 -> 1"
            ]
        );
        assert!(setting_differences(&now, &now).is_empty());
    }
}
