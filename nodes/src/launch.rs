//! `volcal launch`: starts the nodes of a YAML launch description, forwards their output with
//! the node name as prefix, and stops them cleanly on Ctrl-C or when a node marked
//! `on_exit: shutdown` (the sequencer, the solver) ends.
//!
//! The format is the subset of ROS 2's YAML launch files that the node set needs:
//!
//! ```yaml
//! launch:
//!   - arg: {name: bag, default: "campaign_bag"}          # volcal launch FILE bag:=other
//!   - set_env: {name: ROS_LOCALHOST_ONLY, value: "1"}
//!   - node:
//!       pkg: volcal_nodes
//!       exec: volcal_recorder                             # binary next to `volcal`
//!       name: recorder
//!       param:
//!         - {name: bag, value: "$(var bag)"}
//!       remap:
//!         - {from: /campaign/pairs, to: /cmm1/pairs}
//!       respawn: false                                    # restart when it dies
//!       respawn_delay: 1.0
//!       on_exit: shutdown                                 # its end ends the launch
//! ```
//!
//! Substitutions: `$(var NAME)`, `$(env NAME)` / `$(env NAME default)`, and `$(dirname)`, the
//! directory of the launch file. Each node gets `--ros-args -r __node:=NAME -p k:=v -r a:=b`.

use crate::ros::{now_ns, shutdown, NodeArgs};
use anyhow::{anyhow, bail, Context, Result};
use serde_yaml::Value;
use std::collections::BTreeMap;
use std::io::{BufRead, BufReader, Write};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// A node to start.
#[derive(Clone, Debug, PartialEq)]
pub struct NodeSpec {
    pub name: String,
    pub exec: String,
    pub params: BTreeMap<String, String>,
    pub remaps: BTreeMap<String, String>,
    pub respawn: bool,
    pub respawn_delay_s: f64,
    pub shutdown_on_exit: bool,
}

/// A parsed launch description, substitutions applied.
#[derive(Clone, Debug, PartialEq)]
pub struct LaunchDescription {
    pub env: BTreeMap<String, String>,
    pub nodes: Vec<NodeSpec>,
    /// Declared arguments and their values.
    pub args: BTreeMap<String, String>,
}

fn substitute(s: &str, args: &BTreeMap<String, String>, dirname: &str, at: &str) -> Result<String> {
    let mut out = String::new();
    let mut rest = s;
    while let Some(i) = rest.find("$(") {
        out.push_str(&rest[..i]);
        let j = rest[i..].find(')').ok_or_else(|| anyhow!("{at}: unclosed substitution in {s:?}"))? + i;
        let inner: Vec<&str> = rest[i + 2..j].split_whitespace().collect();
        match inner.as_slice() {
            ["var", name] => out.push_str(
                args.get(*name).ok_or_else(|| anyhow!("{at}: $(var {name}): no launch argument {name} is declared"))?,
            ),
            ["env", name] => out.push_str(
                &std::env::var(name)
                    .map_err(|_| anyhow!("{at}: $(env {name}): the environment variable is not set"))?,
            ),
            ["env", name, default] => out.push_str(&std::env::var(name).unwrap_or_else(|_| default.to_string())),
            ["dirname"] => out.push_str(dirname),
            _ => bail!("{at}: unknown substitution $({})", &rest[i + 2..j]),
        }
        rest = &rest[j + 1..];
    }
    out.push_str(rest);
    Ok(out)
}

fn scalar(v: &Value, at: &str) -> Result<String> {
    Ok(match v {
        Value::String(s) => s.clone(),
        Value::Bool(b) => b.to_string(),
        Value::Number(n) => n.to_string(),
        Value::Null => String::new(),
        _ => bail!("{at}: expected a scalar value, got {}", serde_yaml::to_string(v).unwrap_or_default().trim()),
    })
}

fn field<'a>(m: &'a serde_yaml::Mapping, key: &str) -> Option<&'a Value> {
    m.get(Value::String(key.into()))
}

fn map<'a>(v: &'a Value, at: &str) -> Result<&'a serde_yaml::Mapping> {
    v.as_mapping().ok_or_else(|| anyhow!("{at}: expected a mapping"))
}

fn check_keys(m: &serde_yaml::Mapping, allowed: &[&str], at: &str) -> Result<()> {
    for k in m.keys() {
        let k = k.as_str().unwrap_or("?");
        if !allowed.contains(&k) {
            bail!("{at}: unknown key {k:?} (expected one of {})", allowed.join(", "));
        }
    }
    Ok(())
}

impl LaunchDescription {
    /// Reads a launch file; `overrides` are the command line's `name:=value` arguments.
    pub fn load(path: &Path, overrides: &BTreeMap<String, String>) -> Result<LaunchDescription> {
        let text =
            std::fs::read_to_string(path).with_context(|| format!("cannot read launch file {}", path.display()))?;
        let dir =
            path.parent().map(|p| if p.as_os_str().is_empty() { Path::new(".") } else { p }).unwrap_or(Path::new("."));
        let dir = dir.canonicalize().unwrap_or_else(|_| dir.to_path_buf());
        LaunchDescription::parse(&text, &path.display().to_string(), &dir.display().to_string(), overrides)
    }

    /// Parses launch YAML; `name` is used in messages, `dirname` for `$(dirname)`.
    pub fn parse(
        text: &str,
        name: &str,
        dirname: &str,
        overrides: &BTreeMap<String, String>,
    ) -> Result<LaunchDescription> {
        let doc: Value = serde_yaml::from_str(text).map_err(|e| {
            let at = e.location().map(|l| format!(" line {}", l.line())).unwrap_or_default();
            anyhow!("{name}{at}: {e}")
        })?;
        let actions = doc
            .get("launch")
            .and_then(|l| l.as_sequence())
            .ok_or_else(|| anyhow!("{name}: expected a top-level `launch:` list"))?;
        let mut d = LaunchDescription { env: BTreeMap::new(), nodes: Vec::new(), args: BTreeMap::new() };
        let mut used_overrides = Vec::new();
        for (i, action) in actions.iter().enumerate() {
            let at = format!("{name}: launch[{i}]");
            let m = map(action, &at)?;
            if m.len() != 1 {
                bail!("{at}: each entry has exactly one of arg, set_env, node");
            }
            let (kind, body) = m.iter().next().unwrap();
            let kind = kind.as_str().unwrap_or("?");
            let at = format!("{at}.{kind}");
            let body = map(body, &at)?;
            let sub = |v: &Value, what: &str, d: &LaunchDescription| -> Result<String> {
                substitute(&scalar(v, &format!("{at}.{what}"))?, &d.args, dirname, &format!("{at}.{what}"))
            };
            match kind {
                "arg" => {
                    check_keys(body, &["name", "default", "description"], &at)?;
                    let n = scalar(field(body, "name").ok_or_else(|| anyhow!("{at}: missing name"))?, &at)?;
                    let v = match overrides.get(&n) {
                        Some(v) => {
                            used_overrides.push(n.clone());
                            v.clone()
                        }
                        None => match field(body, "default") {
                            Some(v) => sub(v, "default", &d)?,
                            None => bail!("{at}: launch argument {n} has no default; give it as {n}:=VALUE"),
                        },
                    };
                    d.args.insert(n, v);
                }
                "set_env" => {
                    check_keys(body, &["name", "value"], &at)?;
                    let n = scalar(field(body, "name").ok_or_else(|| anyhow!("{at}: missing name"))?, &at)?;
                    let v = sub(field(body, "value").ok_or_else(|| anyhow!("{at}: missing value"))?, "value", &d)?;
                    d.env.insert(n, v);
                }
                "node" => {
                    check_keys(
                        body,
                        &["pkg", "exec", "name", "param", "remap", "respawn", "respawn_delay", "on_exit", "output"],
                        &at,
                    )?;
                    let exec = sub(field(body, "exec").ok_or_else(|| anyhow!("{at}: missing exec"))?, "exec", &d)?;
                    let node_name = match field(body, "name") {
                        Some(v) => sub(v, "name", &d)?,
                        None => exec.trim_start_matches("volcal_").to_string(),
                    };
                    let mut params = BTreeMap::new();
                    if let Some(ps) = field(body, "param") {
                        for (k, p) in
                            ps.as_sequence().ok_or_else(|| anyhow!("{at}.param: expected a list"))?.iter().enumerate()
                        {
                            let pat = format!("{at}.param[{k}]");
                            let pm = map(p, &pat)?;
                            check_keys(pm, &["name", "value"], &pat)?;
                            let n = scalar(field(pm, "name").ok_or_else(|| anyhow!("{pat}: missing name"))?, &pat)?;
                            let v = field(pm, "value").ok_or_else(|| anyhow!("{pat}: missing value"))?;
                            params.insert(n, substitute(&scalar(v, &pat)?, &d.args, dirname, &pat)?);
                        }
                    }
                    let mut remaps = BTreeMap::new();
                    if let Some(rs) = field(body, "remap") {
                        for (k, r) in
                            rs.as_sequence().ok_or_else(|| anyhow!("{at}.remap: expected a list"))?.iter().enumerate()
                        {
                            let rat = format!("{at}.remap[{k}]");
                            let rm = map(r, &rat)?;
                            check_keys(rm, &["from", "to"], &rat)?;
                            let from = scalar(field(rm, "from").ok_or_else(|| anyhow!("{rat}: missing from"))?, &rat)?;
                            let to = scalar(field(rm, "to").ok_or_else(|| anyhow!("{rat}: missing to"))?, &rat)?;
                            remaps.insert(
                                substitute(&from, &d.args, dirname, &rat)?,
                                substitute(&to, &d.args, dirname, &rat)?,
                            );
                        }
                    }
                    let flag = |k: &str| -> Result<bool> {
                        match field(body, k) {
                            None => Ok(false),
                            Some(v) => match sub(v, k, &d)?.as_str() {
                                "true" | "True" => Ok(true),
                                "false" | "False" => Ok(false),
                                o => bail!("{at}.{k}: expected true or false, got {o:?}"),
                            },
                        }
                    };
                    let respawn = flag("respawn")?;
                    let respawn_delay_s = match field(body, "respawn_delay") {
                        None => 1.0,
                        Some(v) => sub(v, "respawn_delay", &d)?
                            .parse::<f64>()
                            .map_err(|_| anyhow!("{at}.respawn_delay: expected seconds"))?,
                    };
                    let shutdown_on_exit = match field(body, "on_exit") {
                        None => false,
                        Some(v) => match sub(v, "on_exit", &d)?.as_str() {
                            "shutdown" => true,
                            o => bail!("{at}.on_exit: only `shutdown` is supported, got {o:?}"),
                        },
                    };
                    if d.nodes.iter().any(|n| n.name == node_name) {
                        bail!("{at}: two nodes are named {node_name}");
                    }
                    d.nodes.push(NodeSpec {
                        name: node_name,
                        exec,
                        params,
                        remaps,
                        respawn,
                        respawn_delay_s,
                        shutdown_on_exit,
                    });
                }
                other => bail!("{at}: unknown action {other:?} (expected arg, set_env or node)"),
            }
        }
        for k in overrides.keys() {
            if !used_overrides.contains(k) {
                let declared: Vec<&String> = d.args.keys().collect();
                bail!(
                    "{name}: no launch argument {k} (declared: {})",
                    if declared.is_empty() {
                        "none".to_string()
                    } else {
                        declared.iter().map(|s| s.as_str()).collect::<Vec<_>>().join(", ")
                    }
                );
            }
        }
        if d.nodes.is_empty() {
            bail!("{name}: no nodes to launch");
        }
        Ok(d)
    }
}

/// Where the node binaries are: `VOLCAL_NODE_DIR`, else next to the running executable (or
/// its parent, for test binaries in `target/*/deps`).
pub fn node_dir() -> Result<PathBuf> {
    if let Ok(d) = std::env::var("VOLCAL_NODE_DIR") {
        return Ok(PathBuf::from(d));
    }
    let exe = std::env::current_exe().context("cannot locate the running executable")?;
    let dir = exe.parent().unwrap_or(Path::new(".")).to_path_buf();
    if dir.join("volcal_recorder").exists() {
        return Ok(dir);
    }
    match dir.parent() {
        Some(p) if p.join("volcal_recorder").exists() => Ok(p.to_path_buf()),
        _ => Ok(dir),
    }
}

/// How a launch ended.
#[derive(Clone, Debug, PartialEq)]
pub struct LaunchOutcome {
    /// Exit code of each node's last run (`None`: ended by a signal).
    pub exits: BTreeMap<String, Option<i32>>,
    /// The launch was ended by Ctrl-C / SIGTERM rather than by a node.
    pub interrupted: bool,
    /// Nodes that failed (non-zero exit not caused by the launch stopping them).
    pub failed: Vec<String>,
}

struct Running {
    spec: NodeSpec,
    child: Option<Child>,
    respawn_at: Option<Instant>,
    exit: Option<Option<i32>>,
}

/// Options of a launch run.
#[derive(Clone, Debug)]
pub struct LaunchOptions {
    /// `ROS_DOMAIN_ID` for the nodes (overrides the file's `set_env` and the environment).
    pub domain: Option<u16>,
    /// How long nodes get to stop after SIGINT before SIGKILL.
    pub stop_timeout: Duration,
    /// Prefix for the launcher's own messages.
    pub quiet: bool,
}

impl Default for LaunchOptions {
    fn default() -> Self {
        LaunchOptions { domain: None, stop_timeout: Duration::from_secs(10), quiet: false }
    }
}

fn say(quiet: bool, msg: &str) {
    if !quiet {
        println!("[launch] {msg}");
        let _ = std::io::stdout().flush();
    }
}

/// The command that runs a node: its binary next to `volcal`, or else (no binary, or one older
/// than `volcal`) `volcal node EXEC` (the `volcal` binary contains every node, so
/// `cargo run -- launch ...` works without building the node binaries).
fn node_command(spec: &NodeSpec, dir: &Path) -> Result<Command> {
    let exe = dir.join(&spec.exec);
    let built_in = std::env::current_exe()
        .ok()
        .filter(|e| e.file_stem().is_some_and(|s| s == "volcal") && crate::node::by_name(&spec.exec).is_some());
    // A node binary older than the running `volcal` was left by an earlier build (cargo builds
    // the node binaries only when asked): the nodes built into `volcal` are the current ones.
    let modified = |p: &Path| std::fs::metadata(p).and_then(|m| m.modified()).ok();
    let stale = match (&built_in, modified(&exe)) {
        (Some(v), Some(node)) => modified(v).is_some_and(|v| node < v),
        _ => false,
    };
    if exe.exists() && !stale {
        return Ok(Command::new(exe));
    }
    let Some(volcal) = built_in else {
        bail!(
            "node {}: executable {} not found (build the node binaries: cargo build -p volcal_nodes --bins; or set VOLCAL_NODE_DIR)",
            spec.name,
            exe.display()
        )
    };
    if stale {
        eprintln!(
            "[launch] note: {} is older than this volcal: running the node built into volcal instead",
            exe.display()
        );
    }
    let mut c = Command::new(volcal);
    c.arg("node").arg(&spec.exec);
    Ok(c)
}

fn spawn(spec: &NodeSpec, dir: &Path, env: &BTreeMap<String, String>) -> Result<Child> {
    let mut cmd = node_command(spec, dir)?;
    cmd.args(NodeArgs::to_command_line(&spec.name, &spec.params, &spec.remaps))
        .envs(env)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped());
    let mut child = cmd.spawn().with_context(|| format!("cannot start node {} ({})", spec.name, spec.exec))?;
    for stream in [
        child.stdout.take().map(|s| Box::new(s) as Box<dyn std::io::Read + Send>),
        child.stderr.take().map(|s| Box::new(s) as Box<dyn std::io::Read + Send>),
    ]
    .into_iter()
    .flatten()
    {
        let name = spec.name.clone();
        std::thread::spawn(move || {
            for line in BufReader::new(stream).lines() {
                let Ok(line) = line else { break };
                let mut out = std::io::stdout().lock();
                let _ = writeln!(out, "[{name}] {line}");
                let _ = out.flush();
            }
        });
    }
    Ok(child)
}

fn signal(child: &Child, sig: libc::c_int) {
    // SAFETY: sending a signal to a child process we started.
    unsafe {
        libc::kill(child.id() as libc::pid_t, sig);
    }
}

/// Runs a launch description to its end.
pub fn run(d: &LaunchDescription, opts: &LaunchOptions) -> Result<LaunchOutcome> {
    shutdown::install();
    let dir = node_dir()?;
    let mut env = d.env.clone();
    if let Some(dom) = opts.domain {
        env.insert("ROS_DOMAIN_ID".into(), dom.to_string());
    }
    env.insert("VOLCAL_SIM_EPOCH_NS".into(), now_ns().to_string());
    let mut nodes: Vec<Running> =
        d.nodes.iter().map(|s| Running { spec: s.clone(), child: None, respawn_at: None, exit: None }).collect();
    let mut stopping: Option<Instant> = None;
    let mut interrupted = false;
    let mut failed = Vec::new();
    let start_all = |nodes: &mut Vec<Running>, failed: &mut Vec<String>| -> Result<()> {
        for n in nodes.iter_mut() {
            match spawn(&n.spec, &dir, &env) {
                Ok(c) => {
                    say(opts.quiet, &format!("started {} (pid {})", n.spec.name, c.id()));
                    n.child = Some(c);
                }
                Err(e) => {
                    failed.push(n.spec.name.clone());
                    return Err(e);
                }
            }
        }
        Ok(())
    };
    if let Err(e) = start_all(&mut nodes, &mut failed) {
        for n in nodes.iter_mut() {
            if let Some(c) = &mut n.child {
                let _ = c.kill();
                let _ = c.wait();
            }
        }
        return Err(e);
    }
    loop {
        if stopping.is_none() && shutdown::requested() {
            interrupted = true;
            say(opts.quiet, "stop requested: stopping the nodes");
            stopping = Some(Instant::now());
            for n in &nodes {
                if let Some(c) = &n.child {
                    signal(c, libc::SIGINT);
                }
            }
        }
        let mut begin_stop = false;
        for n in nodes.iter_mut() {
            if let Some(c) = &mut n.child {
                if let Some(status) = c.try_wait()? {
                    let code = status.code();
                    n.child = None;
                    n.exit = Some(code);
                    let how = match code {
                        Some(0) => "finished".to_string(),
                        Some(k) => format!("exited with status {k}"),
                        None => "was killed by a signal".to_string(),
                    };
                    if stopping.is_some() {
                        say(opts.quiet, &format!("{} {how}", n.spec.name));
                        if code.is_some_and(|k| k != 0) {
                            failed.push(n.spec.name.clone());
                        }
                    } else if n.spec.respawn {
                        say(
                            opts.quiet,
                            &format!("{} {how}; respawning in {:.1} s", n.spec.name, n.spec.respawn_delay_s),
                        );
                        n.respawn_at = Some(Instant::now() + Duration::from_secs_f64(n.spec.respawn_delay_s));
                    } else {
                        say(opts.quiet, &format!("{} {how}", n.spec.name));
                        if code != Some(0) {
                            failed.push(n.spec.name.clone());
                        }
                        if n.spec.shutdown_on_exit {
                            begin_stop = true;
                        }
                    }
                }
            } else if let Some(at) = n.respawn_at {
                if stopping.is_none() && Instant::now() >= at {
                    n.respawn_at = None;
                    let c = spawn(&n.spec, &dir, &env)?;
                    say(opts.quiet, &format!("respawned {} (pid {})", n.spec.name, c.id()));
                    n.child = Some(c);
                }
            }
        }
        if begin_stop && stopping.is_none() {
            if nodes.iter().any(|n| n.child.is_some()) {
                say(opts.quiet, "stopping the other nodes");
            }
            stopping = Some(Instant::now());
            for n in &nodes {
                if let Some(c) = &n.child {
                    signal(c, libc::SIGINT);
                }
            }
        }
        let running = nodes.iter().filter(|n| n.child.is_some()).count();
        let waiting_respawn = nodes.iter().any(|n| n.respawn_at.is_some()) && stopping.is_none();
        if running == 0 && !waiting_respawn {
            break;
        }
        if let Some(s) = stopping {
            if s.elapsed() > opts.stop_timeout {
                for n in nodes.iter_mut() {
                    if let Some(c) = &mut n.child {
                        say(
                            opts.quiet,
                            &format!(
                                "{} did not stop within {:.0} s: killing it",
                                n.spec.name,
                                opts.stop_timeout.as_secs_f64()
                            ),
                        );
                        let _ = c.kill();
                    }
                }
            }
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    // Let the output threads print the last lines.
    std::thread::sleep(Duration::from_millis(50));
    Ok(LaunchOutcome {
        exits: nodes.iter().map(|n| (n.spec.name.clone(), n.exit.flatten())).collect(),
        interrupted,
        failed,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    const FILE: &str = r#"
launch:
  - arg: {name: bag, default: "$(dirname)/out"}
  - arg: {name: rate, default: 100}
  - set_env: {name: ROS_LOCALHOST_ONLY, value: "1"}
  - node:
      pkg: volcal_nodes
      exec: volcal_machine
      name: machine
      param:
        - {name: rate_hz, value: "$(var rate)"}
        - {name: verbose, value: true}
      remap:
        - {from: /machine/position, to: /cmm/position}
      respawn: true
  - node:
      exec: volcal_recorder
      param:
        - {name: bag, value: "$(var bag)"}
      on_exit: shutdown
"#;

    #[test]
    fn parses_ros2_yaml_launch_subset() {
        let mut o = BTreeMap::new();
        o.insert("rate".to_string(), "250".to_string());
        let d = LaunchDescription::parse(FILE, "t.yaml", "/cfg", &o).unwrap();
        assert_eq!(d.env["ROS_LOCALHOST_ONLY"], "1");
        assert_eq!(d.nodes.len(), 2);
        let m = &d.nodes[0];
        assert_eq!((m.name.as_str(), m.exec.as_str()), ("machine", "volcal_machine"));
        assert_eq!(m.params["rate_hz"], "250");
        assert_eq!(m.params["verbose"], "true");
        assert_eq!(m.remaps["/machine/position"], "/cmm/position");
        assert!(m.respawn && !m.shutdown_on_exit);
        let r = &d.nodes[1];
        assert_eq!(r.name, "recorder");
        assert_eq!(r.params["bag"], "/cfg/out");
        assert!(r.shutdown_on_exit);
    }

    #[test]
    fn repository_launch_configs_parse() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../launch_configs");
        let mut n = 0;
        for e in std::fs::read_dir(&dir).unwrap() {
            let p = e.unwrap().path();
            if p.extension().is_some_and(|x| x == "yaml") {
                let mut o = BTreeMap::new();
                // `--bag` for the configs that take one (the viz node's does not).
                let text = std::fs::read_to_string(&p).unwrap();
                if text.contains("{name: bag,") {
                    o.insert("bag".to_string(), "/tmp/b".to_string());
                }
                // The cell configs need the cell's joints.
                if text.contains("{name: joint_names}") {
                    o.insert("joint_names".to_string(), "x=a,y=b,z=c".to_string());
                }
                let d = LaunchDescription::load(&p, &o).unwrap_or_else(|e| panic!("{}: {e:#}", p.display()));
                for node in &d.nodes {
                    assert!(crate::node::by_name(&node.exec).is_some(), "{}: unknown node {}", p.display(), node.exec);
                    for v in node.params.values().filter(|v| v.ends_with(".yaml")) {
                        assert!(Path::new(v).exists(), "{}: {v} does not exist", p.display());
                    }
                }
                n += 1;
            }
        }
        assert!(n >= 5);
    }

    #[test]
    fn errors_name_the_place() {
        let e = LaunchDescription::parse(FILE, "t.yaml", "/cfg", &[("nope".to_string(), "1".to_string())].into())
            .unwrap_err();
        assert!(format!("{e}").contains("no launch argument nope"), "{e}");
        let bad = "launch:\n  - node: {exec: x, parm: []}\n";
        let e = LaunchDescription::parse(bad, "b.yaml", ".", &BTreeMap::new()).unwrap_err();
        assert!(format!("{e}").contains("b.yaml: launch[0].node: unknown key \"parm\""), "{e}");
        let bad = "launch:\n  - node: {exec: x, param: [{name: a, value: \"$(var q)\"}]}\n";
        let e = LaunchDescription::parse(bad, "b.yaml", ".", &BTreeMap::new()).unwrap_err();
        assert!(format!("{e}").contains("$(var q)"), "{e}");
    }
}
