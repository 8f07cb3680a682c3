//! Node command lines in ROS 2's form, so that a node runs the same under `volcal launch` and
//! by hand:
//!
//! ```text
//! volcal_machine --ros-args -r __node:=machine -p machine:=demo_cmm.yaml -p rate_hz:=200 \
//!     -r /machine/position:=/cmm/position --params-file params.yaml
//! ```
//!
//! Parameter values are YAML scalars (`200`, `0.5`, `true`, `path.yaml`). A params file is
//! ROS 2's: `<node name or /**>: {ros__parameters: {name: value}}`. Every parameter a node
//! reads is marked; [`NodeArgs::unused`] lists the others, so that a typo is reported.

use anyhow::{anyhow, bail, Context, Result};
use serde::de::DeserializeOwned;
use std::cell::RefCell;
use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// Parsed node arguments.
#[derive(Debug, Default)]
pub struct NodeArgs {
    /// Node name (`-r __node:=name`), if given.
    pub name: Option<String>,
    /// Node namespace (`-r __ns:=/ns`), if given.
    pub namespace: Option<String>,
    params: BTreeMap<String, serde_yaml::Value>,
    /// Topic remaps, from -> to.
    pub remaps: BTreeMap<String, String>,
    used: RefCell<BTreeSet<String>>,
}

impl NodeArgs {
    /// Parses the process arguments (everything after `--ros-args`; anything before is an error
    /// except `--help`).
    pub fn from_env() -> Result<NodeArgs> {
        let args: Vec<String> = std::env::args().skip(1).collect();
        NodeArgs::parse(&args)
    }

    /// Parses an argument list (without the program name).
    pub fn parse(args: &[String]) -> Result<NodeArgs> {
        let mut out = NodeArgs::default();
        let mut it = args.iter();
        let mut in_ros = false;
        let mut files = Vec::new();
        while let Some(a) = it.next() {
            if a == "--ros-args" {
                in_ros = true;
                continue;
            }
            if a == "--" {
                in_ros = false;
                continue;
            }
            if !in_ros {
                bail!("unexpected argument {a:?}: node arguments go after --ros-args (e.g. --ros-args -p name:=value)");
            }
            let mut value =
                |flag: &str| it.next().cloned().ok_or_else(|| anyhow!("{flag} needs a value (name:=value)"));
            match a.as_str() {
                "-p" | "--param" => {
                    let v = value(a)?;
                    let (k, val) = split_assign(&v)?;
                    out.params.insert(k.to_string(), yaml_scalar(val));
                }
                "-r" | "--remap" => {
                    let v = value(a)?;
                    let (from, to) = split_assign(&v)?;
                    match from {
                        "__node" | "__name" => out.name = Some(to.to_string()),
                        "__ns" => out.namespace = Some(to.to_string()),
                        _ => {
                            out.remaps.insert(from.to_string(), to.to_string());
                        }
                    }
                }
                "--params-file" => files.push(PathBuf::from(value(a)?)),
                "--log-level" => {
                    value(a)?;
                }
                _ => bail!("unknown ROS argument {a:?} (expected -p name:=value, -r from:=to, --params-file FILE)"),
            }
        }
        // Command-line parameters win over the params files.
        for f in files {
            for (k, v) in read_params_file(&f, out.name.as_deref())? {
                out.params.entry(k).or_insert(v);
            }
        }
        Ok(out)
    }

    /// A parameter, deserialised; `None` when absent.
    pub fn get<T: DeserializeOwned>(&self, name: &str) -> Result<Option<T>> {
        self.used.borrow_mut().insert(name.to_string());
        match self.params.get(name) {
            None => Ok(None),
            Some(v) => serde_yaml::from_value(v.clone())
                .map(Some)
                .map_err(|e| anyhow!("parameter {name}: {:?} is not valid here: {e}", scalar_text(v))),
        }
    }

    /// A parameter with a default.
    pub fn get_or<T: DeserializeOwned>(&self, name: &str, default: T) -> Result<T> {
        Ok(self.get(name)?.unwrap_or(default))
    }

    /// A required parameter.
    pub fn require<T: DeserializeOwned>(&self, name: &str) -> Result<T> {
        self.get(name)?.ok_or_else(|| anyhow!("parameter {name} is required (-p {name}:=...)"))
    }

    /// A path parameter (an empty value counts as absent).
    pub fn path(&self, name: &str) -> Result<Option<PathBuf>> {
        Ok(self.get::<String>(name)?.filter(|s| !s.is_empty()).map(PathBuf::from))
    }

    /// Parameters given but never read (typos, or parameters of another node).
    pub fn unused(&self) -> Vec<String> {
        let used = self.used.borrow();
        self.params.keys().filter(|k| !used.contains(*k)).cloned().collect()
    }

    /// Applies the remaps to a topic name.
    pub fn remap(&self, topic: &str) -> String {
        self.remaps.get(topic).cloned().unwrap_or_else(|| topic.to_string())
    }

    /// Command-line form of a parameter map and remaps (what `volcal launch` passes).
    pub fn to_command_line(
        name: &str,
        params: &BTreeMap<String, String>,
        remaps: &BTreeMap<String, String>,
    ) -> Vec<String> {
        let mut v = vec!["--ros-args".to_string(), "-r".into(), format!("__node:={name}")];
        for (k, val) in params {
            v.push("-p".into());
            v.push(format!("{k}:={val}"));
        }
        for (from, to) in remaps {
            v.push("-r".into());
            v.push(format!("{from}:={to}"));
        }
        v
    }
}

fn split_assign(s: &str) -> Result<(&str, &str)> {
    s.split_once(":=").ok_or_else(|| anyhow!("{s:?} is not of the form name:=value"))
}

fn yaml_scalar(s: &str) -> serde_yaml::Value {
    if s.is_empty() {
        // `-p plan:=` is an empty string (ROS 2 reads it so too), not YAML's null.
        return serde_yaml::Value::String(String::new());
    }
    serde_yaml::from_str(s).unwrap_or_else(|_| serde_yaml::Value::String(s.to_string()))
}

fn scalar_text(v: &serde_yaml::Value) -> String {
    serde_yaml::to_string(v).map(|s| s.trim().to_string()).unwrap_or_default()
}

/// Reads a ROS 2 params file: `{node or /**: {ros__parameters: {...}}}`.
fn read_params_file(path: &Path, node: Option<&str>) -> Result<BTreeMap<String, serde_yaml::Value>> {
    let text = std::fs::read_to_string(path).with_context(|| format!("cannot read params file {}", path.display()))?;
    let doc: BTreeMap<String, serde_yaml::Value> =
        serde_yaml::from_str(&text).map_err(|e| anyhow!("params file {}: {e}", path.display()))?;
    let mut out = BTreeMap::new();
    for (key, body) in doc {
        let applies = key == "/**" || node.is_some_and(|n| key.trim_start_matches('/') == n);
        if !applies {
            continue;
        }
        let params = body
            .get("ros__parameters")
            .ok_or_else(|| anyhow!("params file {}: {key}: missing ros__parameters", path.display()))?;
        let map: BTreeMap<String, serde_yaml::Value> = serde_yaml::from_value(params.clone())
            .map_err(|e| anyhow!("params file {}: {key}.ros__parameters: {e}", path.display()))?;
        out.extend(map);
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn s(v: &[&str]) -> Vec<String> {
        v.iter().map(|x| x.to_string()).collect()
    }

    #[test]
    fn parses_params_remaps_and_reports_unused() {
        let a = NodeArgs::parse(&s(&[
            "--ros-args",
            "-r",
            "__node:=m1",
            "-p",
            "rate_hz:=200",
            "-p",
            "machine:=a b.yaml",
            "-p",
            "loopback:=true",
            "-r",
            "/machine/position:=/cmm/position",
            "-p",
            "typo:=1",
        ]))
        .unwrap();
        assert_eq!(a.name.as_deref(), Some("m1"));
        assert_eq!(a.get::<f64>("rate_hz").unwrap(), Some(200.0));
        assert_eq!(a.get::<String>("machine").unwrap().as_deref(), Some("a b.yaml"));
        assert!(a.get::<bool>("loopback").unwrap().unwrap());
        assert_eq!(a.remap("/machine/position"), "/cmm/position");
        assert_eq!(a.remap("/other"), "/other");
        assert_eq!(a.unused(), vec!["typo".to_string()]);
        let e = NodeArgs::parse(&s(&["--ros-args", "-p", "plan:="])).unwrap();
        assert_eq!(e.path("plan").unwrap(), None);
        let e = a.get::<f64>("machine").unwrap_err();
        assert!(format!("{e}").contains("parameter machine"), "{e}");
        assert!(NodeArgs::parse(&s(&["-p", "x:=1"])).is_err());
        assert!(NodeArgs::parse(&s(&["--ros-args", "-p", "x=1"])).is_err());
    }

    #[test]
    fn command_line_round_trip() {
        let mut p = BTreeMap::new();
        p.insert("settle_s".to_string(), "0.05".to_string());
        let mut r = BTreeMap::new();
        r.insert("/a".to_string(), "/b".to_string());
        let a = NodeArgs::parse(&NodeArgs::to_command_line("deflector", &p, &r)).unwrap();
        assert_eq!(a.name.as_deref(), Some("deflector"));
        assert_eq!(a.get::<f64>("settle_s").unwrap(), Some(0.05));
        assert_eq!(a.remap("/a"), "/b");
    }
}
