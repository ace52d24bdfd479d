//! The suite file (`roitrack-pnp-suite/1`): one-instance problems, each tagged with its family, read and validated
//! into a [`PnpSuite`].

use std::path::Path;

use serde_json::Value;

use super::json::{array, expected, field, join, object};
use super::problem::{PnpProblem, parse_problem, validate};
use super::{PnpError, SUITE_FORMAT};

/// One problem of a suite: the family it was drawn from and the problem (one instance, its noise given).
#[derive(Debug, Clone)]
pub struct SuiteProblem {
    /// The family's name, as the suite file gives it.
    pub family: String,
    /// The problem: one instance.
    pub problem: PnpProblem,
}

/// A validated suite of one-instance PnP problems (format `roitrack-pnp-suite/1`, see the
/// [module documentation](super)).
#[derive(Debug, Clone)]
pub struct PnpSuite {
    /// The problems, in the file's order.
    pub problems: Vec<SuiteProblem>,
}

impl PnpSuite {
    /// Parses and validates a suite file's text; every refusal names the problem (`problems[k]`, with its family
    /// once known) and the field.
    ///
    /// ```
    /// use roitrack_bench::pnp::PnpSuite;
    /// let error = PnpSuite::from_json(r#"{"format": "roitrack-pnp-suite/1", "problems": [{"problem": {}}]}"#)
    ///     .unwrap_err();
    /// assert_eq!(error.message, "problems[0].family is missing");
    /// ```
    pub fn from_json(text: &str) -> Result<Self, PnpError> {
        let value: Value = serde_json::from_str(text)
            .map_err(|e| PnpError::new(format!("not a valid PnP suite: {e}")))?;
        let top = object(&value, "")?;
        let format = field(top, "", "format")?;
        if format.as_str() != Some(SUITE_FORMAT) {
            return Err(PnpError::new(format!(
                "format is {format}, expected {SUITE_FORMAT:?}"
            )));
        }
        let entries = array(field(top, "", "problems")?, "problems")?;
        if entries.is_empty() {
            return Err(PnpError::new("problems: the suite has no problems"));
        }
        let problems = entries
            .iter()
            .enumerate()
            .map(|(k, entry)| suite_problem(entry, &format!("problems[{k}]")))
            .collect::<Result<Vec<_>, _>>()?;
        Ok(Self { problems })
    }

    /// Reads and validates a suite file; every refusal names the file, then as [`PnpSuite::from_json`].
    pub fn read(path: &Path) -> Result<Self, PnpError> {
        let text = std::fs::read_to_string(path).map_err(|e| {
            PnpError::new(format!(
                "cannot read the suite file {}: {e}",
                path.display()
            ))
        })?;
        Self::from_json(&text)
            .map_err(|e| PnpError::new(format!("suite file {}: {}", path.display(), e.message)))
    }
}

/// One entry of a suite's `problems`, found at `path`.
fn suite_problem(entry: &Value, path: &str) -> Result<SuiteProblem, PnpError> {
    let fields = object(entry, path)?;
    let family_value = field(fields, path, "family")?;
    let family = family_value
        .as_str()
        .ok_or_else(|| expected(&join(path, "family"), "a string", family_value))?
        .to_owned();
    // From here on the family is named too: the generator's tables are by family.
    let named = |e: PnpError| PnpError::new(format!("{} (family {family:?})", e.message));
    let problem_path = join(path, "problem");
    let file = parse_problem(field(fields, path, "problem")?, &problem_path).map_err(named)?;
    // A suite gives each problem's noise and one instance: its report is one pose and one time per problem.
    if file.noise_px.is_none() {
        return Err(named(PnpError::new(format!(
            "{problem_path}.noise_px is missing (a suite problem gives its pixels' noise)"
        ))));
    }
    if file.instances.len() != 1 {
        return Err(named(PnpError::new(format!(
            "{problem_path}.instances: a suite problem has exactly one instance, got {}",
            file.instances.len()
        ))));
    }
    let problem = validate(file, &problem_path).map_err(named)?;
    Ok(SuiteProblem { family, problem })
}

#[cfg(test)]
mod tests {
    use serde_json::json;

    use super::*;
    use crate::pnp::fixtures::suite_value;

    fn suite_error(value: &Value) -> String {
        PnpSuite::from_json(&value.to_string()).unwrap_err().message
    }

    #[test]
    fn suite_refusals_name_the_problem_and_field() {
        let mut value = suite_value(3);
        value["format"] = json!("roitrack-pnp-problem/1");
        assert_eq!(
            suite_error(&value),
            "format is \"roitrack-pnp-problem/1\", expected \"roitrack-pnp-suite/1\""
        );
        assert_eq!(
            suite_error(&json!({"format": SUITE_FORMAT, "problems": []})),
            "problems: the suite has no problems"
        );
        assert_eq!(
            suite_error(&json!({"format": SUITE_FORMAT})),
            "problems is missing"
        );

        let mut value = suite_value(3);
        value["problems"][1]["problem"]
            .as_object_mut()
            .unwrap()
            .remove("noise_px");
        assert_eq!(
            suite_error(&value),
            "problems[1].problem.noise_px is missing (a suite problem gives its pixels' noise) (family \"b\")"
        );

        let mut value = suite_value(3);
        let instance = value["problems"][0]["problem"]["instances"][0].clone();
        value["problems"][0]["problem"]["instances"] = json!([instance.clone(), instance]);
        assert_eq!(
            suite_error(&value),
            "problems[0].problem.instances: a suite problem has exactly one instance, got 2 (family \"a\")"
        );

        let mut value = suite_value(3);
        value["problems"][2]["problem"]["intrinsics"]["fx_px"] = json!("1500");
        assert_eq!(
            suite_error(&value),
            "problems[2].problem.intrinsics.fx_px: expected a number, got the string \"1500\" (family \"a\")"
        );

        let mut value = suite_value(3);
        value["problems"][1]["problem"]["instances"][0]["pixels"][3] = json!([1.0]);
        assert_eq!(
            suite_error(&value),
            "problems[1].problem.instances[0].pixels[3]: expected an array of 2 numbers, got an array of 1 \
             (family \"b\")"
        );

        let mut value = suite_value(2);
        value["problems"][1]["problem"]["instances"][0]["pixels"]
            .as_array_mut()
            .unwrap()
            .pop();
        assert_eq!(
            suite_error(&value),
            "problems[1].problem.instances[0].pixels: 15 pixels for 16 model points (family \"b\")"
        );

        let mut value = suite_value(2);
        value["problems"][0]["problem"]["noise_px"] = json!(-0.5);
        assert_eq!(
            suite_error(&value),
            "problems[0].problem.noise_px must be a positive number, got -0.5 (family \"a\")"
        );

        let mut value = suite_value(2);
        value["problems"][1]["family"] = json!(3);
        assert_eq!(
            suite_error(&value),
            "problems[1].family: expected a string, got the number 3"
        );
        assert!(
            PnpSuite::from_json("[1, 2")
                .unwrap_err()
                .message
                .starts_with("not a valid PnP suite")
        );
    }

    #[test]
    fn suite_file_is_named() {
        let dir = tempfile::tempdir().unwrap();
        let missing = dir.path().join("missing.json");
        let message = PnpSuite::read(&missing).unwrap_err().message;
        assert!(
            message.starts_with(&format!(
                "cannot read the suite file {}: ",
                missing.display()
            )),
            "{message}"
        );
        let bad = dir.path().join("bad.json");
        let mut value = suite_value(2);
        value["problems"][1]["problem"]["instances"][0]["cam_r_obj"][0][0] = json!(2.0);
        std::fs::write(&bad, value.to_string()).unwrap();
        let message = PnpSuite::read(&bad).unwrap_err().message;
        assert!(
            message.starts_with(&format!(
                "suite file {}: problems[1].problem.instances[0].cam_r_obj is not a rotation matrix",
                bad.display()
            )) && message.ends_with("(family \"b\")"),
            "{message}"
        );
        let good = dir.path().join("good.json");
        std::fs::write(&good, suite_value(1).to_string()).unwrap();
        assert_eq!(PnpSuite::read(&good).unwrap().problems.len(), 1);
    }
}
