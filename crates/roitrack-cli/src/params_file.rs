//! `roitrack ros2-node --params-file FILE.yaml` (feature `ros2`): the node's options from a ROS 2 parameters file, the
//! format `ros2 run ... --ros-args --params-file` and launch files read:
//!
//! ```text
//! roitrack:                 # the node's name (or /roitrack, /NS/roitrack, /**, /**/roitrack)
//!   ros__parameters:
//!     target: target.csv    # each key an option of ros2-node, its long name with _ for -
//!     every: 10
//!     ros2_interface: [127.0.0.1]
//! ```
//!
//! The file's parameters become the options they name, put before the command line's, and an option the command
//! line gives (or one that conflicts with an option the command line gives) is not taken from the file: the command
//! line wins. Every parameter is checked as its option is (its value parser), and an unknown key, a value of the
//! wrong type, an entry without `ros__parameters` or a file with no entry for the node is an error naming the file,
//! the key and its line, before anything runs.

use std::ffi::OsString;
use std::path::Path;

use anyhow::{Result, anyhow, bail};
use clap::{Arg, ArgAction, Command};
use serde_yaml_ng::Value;

/// The node's name, as the entries of a parameters file name it (`roitrack_ros::ros2::NODE_NAME`).
const NODE_NAME: &str = roitrack_ros::ros2::NODE_NAME;

/// The option that names the file.
const PARAMS_FILE: &str = "params-file";

/// The largest parameters file read (a ROS 2 parameters file is a few kilobytes).
const MAX_FILE_BYTES: u64 = 1 << 20;

/// One parameter of the file, as the options it stands for.
#[derive(Debug, Clone, PartialEq)]
pub struct Param {
    /// The key, as the file writes it (`noise_px`).
    pub key: String,
    /// The option's long name (`noise-px`).
    pub long: String,
    /// The option's values, as the command line would give them (none for a flag set to true).
    pub values: Vec<String>,
    /// Whether the option is a flag (a YAML bool: `true` gives it, `false` leaves it out).
    pub flag: bool,
}

/// `argv` (the whole command line, the program first) with the parameters of `ros2-node --params-file FILE` put
/// before the node's own options; `argv` unchanged for another command or without --params-file. `cli` is the
/// program's command, whose subcommand `ros2-node` gives the options.
pub fn expand(argv: Vec<OsString>, cli: &Command) -> Result<Vec<OsString>> {
    let Some(node) = cli.find_subcommand("ros2-node") else {
        return Ok(argv);
    };
    // `roitrack ros2-node ...`: the program takes no options of its own before its command.
    if argv.get(1).and_then(|a| a.to_str()) != Some("ros2-node") {
        return Ok(argv);
    }
    let own = &argv[2..];
    let Some(path) = given_value(own, PARAMS_FILE) else {
        // Without the option, or without its value (which clap then reports).
        return Ok(argv);
    };
    let namespace = given_value(own, "ros2-namespace");
    let params = read(Path::new(&path), node, namespace.as_deref())?;
    let given: Vec<&Arg> = node
        .get_arguments()
        .filter(|arg| is_given(own, arg))
        .collect();
    let mut expanded = argv[..2].to_vec();
    for param in &params {
        let arg = node
            .get_arguments()
            .find(|a| a.get_long() == Some(param.long.as_str()))
            .expect("a parameter is an option of the node");
        // The command line wins: over the option itself, and over an option that conflicts with one it gives.
        // (A conflict is declared on either of the two options.)
        let conflicts = |a: &Arg, b: &Arg| {
            node.get_arg_conflicts_with(a)
                .iter()
                .any(|c| c.get_id() == b.get_id())
        };
        let overridden = given
            .iter()
            .any(|g| g.get_id() == arg.get_id() || conflicts(g, arg) || conflicts(arg, g));
        if overridden {
            continue;
        }
        if param.flag {
            if param.values.is_empty() {
                expanded.push(format!("--{}", param.long).into());
            }
            continue;
        }
        for value in &param.values {
            // `--key=value`: a value that begins with `-` is not taken for an option.
            expanded.push(format!("--{}={value}", param.long).into());
        }
    }
    expanded.extend(own.iter().cloned());
    Ok(expanded)
}

/// The value of `--NAME VALUE` or `--NAME=VALUE` among the node's own options.
fn given_value(own: &[OsString], name: &str) -> Option<OsString> {
    let long = format!("--{name}");
    let prefix = format!("--{name}=");
    let mut tokens = own.iter();
    while let Some(token) = tokens.next() {
        let text = token.to_string_lossy();
        if text == "--" {
            return None;
        }
        if text == long {
            return tokens.next().cloned();
        }
        if let Some(value) = text.strip_prefix(&prefix) {
            return Some(value.into());
        }
    }
    None
}

/// Whether the command line gives `arg` (by its long name, an alias or its short name).
fn is_given(own: &[OsString], arg: &Arg) -> bool {
    let mut longs: Vec<&str> = arg.get_long().into_iter().collect();
    longs.extend(arg.get_all_aliases().unwrap_or_default());
    let short = arg.get_short().map(|c| format!("-{c}"));
    own.iter()
        .map(|t| t.to_string_lossy())
        .take_while(|t| *t != "--")
        .any(|t| {
            longs.iter().any(|l| {
                t.strip_prefix("--")
                    .is_some_and(|rest| rest == *l || rest.starts_with(&format!("{l}=")))
            }) || short.as_deref().is_some_and(|s| t.starts_with(s))
        })
}

/// Reads the parameters of the node in `path`: the entries `/**`, `/**/roitrack`, then `roitrack` or `/roitrack`,
/// then `/NS/roitrack` when `namespace` (the command line's --ros2-namespace) is `/NS`, a later one overriding an
/// earlier one key by key (ROS 2's order: the node's own name over a wildcard). Entries of other nodes are left out.
pub fn read(
    path: &Path,
    node: &Command,
    namespace: Option<&std::ffi::OsStr>,
) -> Result<Vec<Param>> {
    let metadata =
        std::fs::metadata(path).map_err(|e| anyhow!("--params-file {}: {e}", path.display()))?;
    if !metadata.is_file() {
        bail!("--params-file {}: not a file", path.display());
    }
    if metadata.len() > MAX_FILE_BYTES {
        bail!(
            "--params-file {}: {} bytes, more than a parameters file's {MAX_FILE_BYTES}",
            path.display(),
            metadata.len()
        );
    }
    let text = std::fs::read_to_string(path)
        .map_err(|e| anyhow!("--params-file {}: {e}", path.display()))?;
    let namespace = namespace.map(|n| n.to_string_lossy().into_owned());
    parse(&text, node, namespace.as_deref())
        .map_err(|e| anyhow!("--params-file {}: {e}", path.display()))
}

/// The entry names that apply to the node, from the weakest to the strongest.
fn entry_rank(name: &str, namespace: Option<&str>) -> Option<usize> {
    let own = format!("/{NODE_NAME}");
    match name {
        "/**" => Some(0),
        _ if name == format!("/**{own}") => Some(1),
        _ if name == NODE_NAME || name == own => Some(2),
        _ => {
            let ns = namespace?.trim_end_matches('/');
            let ns = if ns.starts_with('/') {
                ns.to_string()
            } else {
                format!("/{ns}")
            };
            (name == format!("{ns}{own}")).then_some(3)
        }
    }
}

/// The 1-based line of the first line at or after `from` (0-based) that begins, indented, with `key:`.
fn line_of(text: &str, key: &str, from: usize) -> Option<usize> {
    let quoted = [
        format!("{key}:"),
        format!("\"{key}\":"),
        format!("'{key}':"),
    ];
    text.lines()
        .enumerate()
        .skip(from)
        .find(|(_, line)| {
            let line = line.trim_start().trim_start_matches("- ");
            quoted.iter().any(|q| line.starts_with(q.as_str()))
        })
        .map(|(k, _)| k + 1)
}

/// "line N: " when the line is known.
fn at(line: Option<usize>) -> String {
    line.map_or_else(String::new, |n| format!("line {n}: "))
}

/// A YAML value's kind, for messages.
fn kind(value: &Value) -> &'static str {
    match value {
        Value::Null => "nothing (null)",
        Value::Bool(_) => "a bool",
        Value::Number(_) => "a number",
        Value::String(_) => "a string",
        Value::Sequence(_) => "a list",
        Value::Mapping(_) => "a mapping",
        Value::Tagged(_) => "a tagged value",
    }
}

/// The parameters of the node in a parameters file's text (see [`read`]), each checked by its option's value parser.
pub fn parse(text: &str, node: &Command, namespace: Option<&str>) -> Result<Vec<Param>> {
    let document: Value = serde_yaml_ng::from_str(text).map_err(|e| match e.location() {
        Some(l) => anyhow!("line {}, column {}: not YAML: {e}", l.line(), l.column()),
        None => anyhow!("not YAML: {e}"),
    })?;
    let Value::Mapping(entries) = document else {
        bail!(
            "a ROS 2 parameters file is a mapping of node names (`{NODE_NAME}:` or `/**:`) to `ros__parameters:`, \
             and this is {}",
            kind(&document)
        );
    };
    let mut applying: Vec<(usize, String, &Value)> = Vec::new();
    let mut names = Vec::new();
    for (name, entry) in &entries {
        let Value::String(name) = name else {
            bail!(
                "a node name is a string, and the file has {} as one",
                kind(name)
            );
        };
        names.push(name.clone());
        if let Some(rank) = entry_rank(name, namespace) {
            applying.push((rank, name.clone(), entry));
        }
    }
    if applying.is_empty() {
        bail!(
            "no entry for the node {NODE_NAME} (`{NODE_NAME}:`, `/{NODE_NAME}:`, `/NS/{NODE_NAME}:` with \
             --ros2-namespace /NS, or `/**:`); the file's entries: {}",
            if names.is_empty() {
                "none".to_string()
            } else {
                names.join(", ")
            }
        );
    }
    applying.sort_by_key(|(rank, ..)| *rank);
    let mut params: Vec<Param> = Vec::new();
    for (_, name, entry) in applying {
        let entry_line = line_of(text, &name, 0);
        let from = entry_line.unwrap_or(1) - 1;
        let Value::Mapping(fields) = entry else {
            bail!(
                "{}{name}: expected `ros__parameters:` under the node's name, and it is {}",
                at(entry_line),
                kind(entry)
            );
        };
        let mut parameters = None;
        for (field, value) in fields {
            match field.as_str() {
                Some("ros__parameters") => parameters = Some(value),
                _ => {
                    let field_text = field
                        .as_str()
                        .map_or_else(|| kind(field).to_string(), str::to_string);
                    bail!(
                        "{}{name}: unknown key {field_text:?}: a node's entry holds only `ros__parameters:`",
                        at(field
                            .as_str()
                            .and_then(|f| line_of(text, f, from))
                            .or(entry_line)),
                    );
                }
            }
        }
        let Some(parameters) = parameters else {
            bail!(
                "{}{name}: no `ros__parameters:` (a node's entry is `{name}:` then `ros__parameters:` then the \
                 keys)",
                at(entry_line)
            );
        };
        let parameters_line = line_of(text, "ros__parameters", from);
        let from = parameters_line.unwrap_or(entry_line.unwrap_or(1)) - 1;
        let keys = match parameters {
            Value::Mapping(keys) => keys.clone(),
            // `ros__parameters:` with nothing under it: no parameters.
            Value::Null => Default::default(),
            other => bail!(
                "{}{name}: ros__parameters is {}, and it must be a mapping of keys to values",
                at(parameters_line),
                kind(other)
            ),
        };
        for (key, value) in &keys {
            let Some(key) = key.as_str() else {
                bail!(
                    "{}{name}: a parameter's key is a string, and this one is {}",
                    at(parameters_line),
                    kind(key)
                );
            };
            let line = line_of(text, key, from);
            let param = parameter(node, key, value)
                .map_err(|e| anyhow!("{}{name}: ros__parameters: {key}: {e}", at(line)))?;
            // A stronger entry overrides a weaker one's key.
            params.retain(|p| p.key != param.key);
            params.push(param);
        }
    }
    Ok(params)
}

/// The keys a file may give: the node's options but --params-file and --help, with `_` for `-`.
fn known_keys(node: &Command) -> Vec<String> {
    node.get_arguments()
        .filter_map(Arg::get_long)
        .filter(|l| *l != PARAMS_FILE && *l != "help")
        .map(|l| l.replace('-', "_"))
        .collect()
}

/// One parameter: its option, its values as text, each checked by the option's value parser.
fn parameter(node: &Command, key: &str, value: &Value) -> Result<Param> {
    let long = key.replace('_', "-");
    let arg = node
        .get_arguments()
        .find(|a| a.get_long() == Some(long.as_str()))
        .filter(|_| !key.contains('-') && long != PARAMS_FILE && long != "help");
    let Some(arg) = arg else {
        bail!(
            "unknown key: not an option of ros2-node (the keys are its options' long names with _ for -: {})",
            known_keys(node).join(", ")
        );
    };
    let scalar = |value: &Value| -> Result<String> {
        match value {
            Value::String(s) => Ok(s.clone()),
            Value::Number(n) => Ok(n.to_string()),
            other => bail!("expected a string or a number, and it is {}", kind(other)),
        }
    };
    let (values, flag) = match arg.get_action() {
        ArgAction::SetTrue => match value {
            Value::Bool(true) => (Vec::new(), true),
            Value::Bool(false) => (vec![String::new()], true),
            other => bail!("expected a bool (true or false), and it is {}", kind(other)),
        },
        ArgAction::Append => match value {
            Value::Sequence(items) => {
                (items.iter().map(scalar).collect::<Result<Vec<_>>>()?, false)
            }
            other => (vec![scalar(other)?], false),
        },
        ArgAction::Set => (vec![scalar(value)?], false),
        other => bail!("the option's action {other:?} cannot be given by a parameters file"),
    };
    if !flag {
        for text in &values {
            check_value(arg, text)?;
        }
    }
    Ok(Param {
        key: key.to_string(),
        long,
        values,
        flag,
    })
}

/// Checks `text` by the option's own value parser (the ranges and names the command line checks).
fn check_value(arg: &Arg, text: &str) -> Result<()> {
    let long = arg.get_long().expect("an option with a long name");
    // clap (without its feature `string`) names options by static strings: the name, a few bytes per parameter of
    // the file, lives as long as the process.
    let name: &'static str = Box::leak(long.to_string().into_boxed_str());
    let mut single = Arg::new(arg.get_id().clone())
        .long(name)
        .value_parser(arg.get_value_parser().clone())
        .action(ArgAction::Set)
        .allow_hyphen_values(true);
    if let Some(names) = arg.get_value_names() {
        single = single.value_names(names.to_vec());
    }
    if let Some(range) = arg.get_num_args() {
        single = single.num_args(range);
    }
    let command = Command::new("ros2-node").no_binary_name(true).arg(single);
    match command.try_get_matches_from([format!("--{long}"), text.to_string()]) {
        Ok(_) => Ok(()),
        Err(e) => {
            let message = e.to_string();
            let first = message.lines().next().unwrap_or_default();
            bail!("{}", first.strip_prefix("error: ").unwrap_or(first))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::CommandFactory;

    fn node() -> Command {
        let mut cli = crate::Cli::command();
        cli.build();
        cli.find_subcommand("ros2-node").unwrap().clone()
    }

    fn params(text: &str) -> Result<Vec<Param>> {
        parse(text, &node(), None)
    }

    fn error(text: &str) -> String {
        format!("{:#}", params(text).unwrap_err())
    }

    #[test]
    fn a_good_file_gives_every_option_it_names() {
        let text = "\
/**:
  ros__parameters:
    every: 5
    frame_id: wildcard
roitrack:
  ros__parameters:
    target: sim/target.csv
    camera: sim/camera.yaml
    measurement_topic: /robot/centroids
    estimator: kalman
    every: 10
    noise_px: 0.25
    idle_s: 2.5
    ros2_domain: 7
    ros2_interface: [127.0.0.1, 10.0.0.2]
";
        let params = params(text).unwrap();
        let get = |key: &str| {
            params
                .iter()
                .find(|p| p.key == key)
                .unwrap_or_else(|| panic!("no {key}"))
                .values
                .clone()
        };
        assert_eq!(get("target"), ["sim/target.csv"]);
        assert_eq!(get("measurement_topic"), ["/robot/centroids"]);
        assert_eq!(get("estimator"), ["kalman"]);
        // The node's own entry over the wildcard, key by key.
        assert_eq!(get("every"), ["10"]);
        assert_eq!(get("frame_id"), ["wildcard"]);
        assert_eq!(get("noise_px"), ["0.25"]);
        assert_eq!(get("idle_s"), ["2.5"]);
        assert_eq!(get("ros2_domain"), ["7"]);
        assert_eq!(get("ros2_interface"), ["127.0.0.1", "10.0.0.2"]);
        assert_eq!(params.iter().filter(|p| p.key == "every").count(), 1);
        assert_eq!(
            params.iter().find(|p| p.key == "camera").unwrap().long,
            "camera"
        );
    }

    #[test]
    fn entries_of_other_nodes_and_namespaces_are_left_out() {
        let text = "\
other_node:
  ros__parameters:
    whatever: 1
/robot1/roitrack:
  ros__parameters:
    every: 3
/robot2/roitrack:
  ros__parameters:
    every: 4
";
        let node = node();
        let every = |ns: Option<&str>| parse(text, &node, ns).unwrap()[0].values.clone();
        assert_eq!(every(Some("/robot1")), ["3"]);
        assert_eq!(every(Some("robot2")), ["4"]);
        let none = format!("{:#}", parse(text, &node, None).unwrap_err());
        assert!(
            none.contains("no entry for the node roitrack")
                && none.contains("other_node, /robot1/roitrack, /robot2/roitrack"),
            "{none}"
        );
    }

    #[test]
    fn an_unknown_key_is_named_with_its_line() {
        let e = error("roitrack:\n  ros__parameters:\n    target: t.csv\n    evry: 10\n");
        assert!(
            e.starts_with("line 4: roitrack: ros__parameters: evry: unknown key")
                && e.contains("every"),
            "{e}"
        );
        // --params-file itself, --help and a dashed key are not parameters.
        for key in ["params_file", "help", "noise-px"] {
            let e = error(&format!("roitrack:\n  ros__parameters:\n    {key}: x\n"));
            assert!(e.contains(&format!("{key}: unknown key")), "{e}");
        }
    }

    #[test]
    fn a_value_of_the_wrong_type_or_out_of_range_is_named_with_its_line() {
        for (value, want) in [
            ("ten", "invalid value 'ten' for '--every"),
            ("[1, 2]", "expected a string or a number, and it is a list"),
            (
                "{a: 1}",
                "expected a string or a number, and it is a mapping",
            ),
            (
                "",
                "expected a string or a number, and it is nothing (null)",
            ),
            ("true", "expected a string or a number, and it is a bool"),
            ("0", "invalid value '0' for '--every"),
        ] {
            let e = error(&format!("/**:\n  ros__parameters:\n    every: {value}\n"));
            assert!(
                e.starts_with("line 3: /**: ros__parameters: every: ") && e.contains(want),
                "every: {value}: {e}"
            );
        }
        let e = error("roitrack:\n  ros__parameters:\n    estimator: kalmann\n");
        assert!(
            e.contains("invalid value 'kalmann' for '--estimator"),
            "{e}"
        );
        let e = error("roitrack:\n  ros__parameters:\n    ros2_domain: 300\n");
        assert!(e.contains("line 3") && e.contains("0 to 232"), "{e}");
        let e = error("roitrack:\n  ros__parameters:\n    ros2_interface: [127.0.0.1, [1]]\n");
        assert!(e.contains("it is a list"), "{e}");
    }

    #[test]
    fn a_missing_or_malformed_ros_parameters_is_named() {
        let e = error("roitrack:\n  target: t.csv\n");
        assert!(
            e.starts_with("line 2: roitrack: unknown key \"target\"")
                && e.contains("only `ros__parameters:`"),
            "{e}"
        );
        let e = error("roitrack: {}\n");
        assert!(
            e.starts_with("line 1: roitrack: no `ros__parameters:`"),
            "{e}"
        );
        let e = error("roitrack: 3\n");
        assert!(e.contains("expected `ros__parameters:`"), "{e}");
        let e = error("roitrack:\n  ros__parameters: [1, 2]\n");
        assert!(
            e.starts_with("line 2: roitrack: ros__parameters is a list"),
            "{e}"
        );
        let e = error("- roitrack\n");
        assert!(e.contains("a mapping of node names"), "{e}");
        // Not YAML at all: the parser's line.
        let e = error("roitrack:\n  ros__parameters:\n    every: [10\n");
        assert!(e.starts_with("line ") && e.contains("not YAML"), "{e}");
        // A key given twice in one entry: the parser's error.
        let e = error("roitrack:\n  ros__parameters:\n    every: 1\n    every: 2\n");
        assert!(e.contains("duplicate"), "{e}");
    }

    #[test]
    fn the_command_line_overrides_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("params.yaml");
        std::fs::write(
            &file,
            "roitrack:\n  ros__parameters:\n    target: file.csv\n    every: 10\n    camera_info_topic: /info\n    \
             ros2_interface: [127.0.0.1]\n",
        )
        .unwrap();
        let mut cli = crate::Cli::command();
        cli.build();
        let argv = |extra: &[&str]| -> Vec<String> {
            let mut argv: Vec<OsString> = ["roitrack", "ros2-node", "--params-file"]
                .map(OsString::from)
                .to_vec();
            argv.push(file.clone().into());
            argv.extend(extra.iter().map(OsString::from));
            expand(argv, &cli)
                .unwrap()
                .into_iter()
                .map(|a| a.into_string().unwrap())
                .collect()
        };
        let from_file = argv(&[]);
        for option in [
            "--target=file.csv",
            "--every=10",
            "--camera-info-topic=/info",
            "--ros2-interface=127.0.0.1",
        ] {
            assert!(from_file.contains(&option.to_string()), "{from_file:?}");
        }
        // --every and --camera given: the file's every, and its camera_info_topic (which conflicts with --camera),
        // are left out.
        let overridden = argv(&["--every", "3", "--camera=c.yaml"]);
        assert!(
            !overridden.iter().any(|a| a.starts_with("--every=")),
            "{overridden:?}"
        );
        assert!(
            !overridden
                .iter()
                .any(|a| a.starts_with("--camera-info-topic")),
            "{overridden:?}"
        );
        assert!(overridden.contains(&"--target=file.csv".to_string()));
        assert_eq!(
            &overridden[overridden.len() - 3..],
            ["--every", "3", "--camera=c.yaml"]
        );
        // Another command, or no --params-file: unchanged.
        let plain: Vec<OsString> = ["roitrack", "track", "--params-file", "x"]
            .map(OsString::from)
            .to_vec();
        assert_eq!(expand(plain.clone(), &cli).unwrap(), plain);
        // A file that is not there: named.
        let argv: Vec<OsString> = ["roitrack", "ros2-node", "--params-file", "/no/such.yaml"]
            .map(OsString::from)
            .to_vec();
        let e = format!("{:#}", expand(argv, &cli).unwrap_err());
        assert!(e.starts_with("--params-file /no/such.yaml: "), "{e}");
    }
}
