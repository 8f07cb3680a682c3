//! Generates the Rust message types and the MCAP `ros2msg` schema texts from the `.msg` files.
//!
//! The `.msg` files are the source of truth: `msg/*.msg` is the `volcal_msgs` package,
//! `deps/<package>/msg/*.msg` are the upstream definitions it uses (`std_msgs/Header`,
//! `builtin_interfaces/Time`). The parser accepts the ROS 2 `.msg` subset these files use:
//! primitive types, strings, nested types, unbounded (`T[]`), bounded (`T[<=N]`) and fixed
//! (`T[N]`) arrays, constants (`TYPE NAME=value`) and comments, which become doc comments.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// rosbag2's separator between a definition and each of its dependencies.
const SEPARATOR: &str = "================================================================================";

#[derive(Debug, Clone)]
enum BaseType {
    Primitive(&'static str),
    String,
    Nested { package: String, name: String },
}

#[derive(Debug, Clone)]
enum Array {
    None,
    Unbounded,
    Fixed(usize),
}

#[derive(Debug, Clone)]
struct Field {
    base: BaseType,
    array: Array,
    name: String,
    doc: Vec<String>,
}

#[derive(Debug, Clone)]
struct Constant {
    rust_type: &'static str,
    name: String,
    value: String,
    doc: Vec<String>,
}

#[derive(Debug, Clone)]
struct MsgDef {
    package: String,
    name: String,
    text: String,
    doc: Vec<String>,
    fields: Vec<Field>,
    constants: Vec<Constant>,
}

fn primitive(t: &str) -> Option<&'static str> {
    Some(match t {
        "bool" => "bool",
        "byte" | "char" | "uint8" => "u8",
        "int8" => "i8",
        "int16" => "i16",
        "uint16" => "u16",
        "int32" => "i32",
        "uint32" => "u32",
        "int64" => "i64",
        "uint64" => "u64",
        "float32" => "f32",
        "float64" => "f64",
        _ => return None,
    })
}

fn parse_type(package: &str, t: &str, at: &str) -> (BaseType, Array) {
    let (base, array) = match t.find('[') {
        None => (t, Array::None),
        Some(i) => {
            let inner = t[i + 1..].strip_suffix(']').unwrap_or_else(|| panic!("{at}: malformed array type {t:?}"));
            let array = if inner.is_empty() || inner.starts_with("<=") {
                Array::Unbounded
            } else {
                Array::Fixed(inner.parse().unwrap_or_else(|_| panic!("{at}: bad array size in {t:?}")))
            };
            (&t[..i], array)
        }
    };
    if let Array::Fixed(n) = array {
        assert!(n <= 32, "{at}: fixed arrays longer than 32 are not supported ({t:?})");
    }
    let base = if base == "string" || base.starts_with("string<=") {
        BaseType::String
    } else if let Some(p) = primitive(base) {
        BaseType::Primitive(p)
    } else if base == "Header" {
        BaseType::Nested { package: "std_msgs".into(), name: "Header".into() }
    } else if let Some((pkg, name)) = base.split_once('/') {
        let name = name.strip_prefix("msg/").unwrap_or(name);
        BaseType::Nested { package: pkg.into(), name: name.into() }
    } else {
        BaseType::Nested { package: package.into(), name: base.into() }
    };
    (base, array)
}

fn parse(package: &str, name: &str, text: &str, file: &Path) -> MsgDef {
    let mut def = MsgDef {
        package: package.into(),
        name: name.into(),
        text: text.into(),
        doc: Vec::new(),
        fields: Vec::new(),
        constants: Vec::new(),
    };
    let mut pending: Vec<String> = Vec::new();
    let mut in_header = true;
    for (k, raw) in text.lines().enumerate() {
        let at = format!("{}:{}", file.display(), k + 1);
        let line = raw.trim();
        if let Some(c) = line.strip_prefix('#') {
            pending.push(c.strip_prefix(' ').unwrap_or(c).to_string());
            continue;
        }
        if in_header {
            // The leading comment block describes the whole message.
            def.doc = std::mem::take(&mut pending);
            in_header = false;
        }
        if line.is_empty() {
            pending.clear();
            continue;
        }
        let (decl, trailing) = match line.split_once('#') {
            Some((d, c)) if !d.contains('=') || !d.trim_start().starts_with("string") => (d.trim(), Some(c.trim())),
            _ => (line, None),
        };
        let mut doc = std::mem::take(&mut pending);
        if let Some(c) = trailing {
            doc.push(c.to_string());
        }
        let mut parts = decl.splitn(2, char::is_whitespace);
        let ty = parts.next().unwrap();
        let rest = parts.next().unwrap_or_else(|| panic!("{at}: expected `type name`")).trim();
        if let Some((cname, value)) = rest.split_once('=') {
            let rust_type = if ty == "string" {
                "&'static str"
            } else {
                primitive(ty).unwrap_or_else(|| panic!("{at}: constants must have a primitive type, got {ty:?}"))
            };
            def.constants.push(Constant {
                rust_type,
                name: cname.trim().to_string(),
                value: value.trim().to_string(),
                doc,
            });
        } else {
            let fname = rest.split_whitespace().next().unwrap();
            assert!(
                fname.chars().all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '_'),
                "{at}: field names are lower_snake_case, got {fname:?}"
            );
            let (base, array) = parse_type(package, ty, &at);
            def.fields.push(Field { base, array, name: fname.to_string(), doc });
        }
    }
    def
}

fn rust_type(f: &Field) -> String {
    let base = match &f.base {
        BaseType::Primitive(p) => p.to_string(),
        BaseType::String => "String".into(),
        BaseType::Nested { package, name } => format!("crate::{}::{}", module_of(package), name),
    };
    match f.array {
        Array::None => base,
        Array::Unbounded => format!("Vec<{base}>"),
        Array::Fixed(n) => format!("[{base}; {n}]"),
    }
}

fn module_of(package: &str) -> String {
    if package == "volcal_msgs" {
        "msg".into()
    } else {
        format!("{package}::msg")
    }
}

fn doc_lines(out: &mut String, indent: &str, doc: &[String]) {
    for d in doc {
        if d.is_empty() {
            writeln!(out, "{indent}///").unwrap();
        } else {
            writeln!(out, "{indent}/// {}", d.replace('[', "\\[").replace(']', "\\]")).unwrap();
        }
    }
}

/// Dependencies of a message in first-use order, depth first, without repeats.
fn dependencies(key: &(String, String), all: &BTreeMap<(String, String), MsgDef>, out: &mut Vec<(String, String)>) {
    let def = &all[key];
    for f in &def.fields {
        if let BaseType::Nested { package, name } = &f.base {
            let k = (package.clone(), name.clone());
            assert!(all.contains_key(&k), "{}/{} uses unknown type {}/{}", def.package, def.name, package, name);
            if !out.contains(&k) {
                out.push(k.clone());
                dependencies(&k, all, out);
            }
        }
    }
}

/// The MCAP `ros2msg` schema: the definition, then each dependency after rosbag2's separator
/// and a `MSG: package/Type` line.
fn schema_text(key: &(String, String), all: &BTreeMap<(String, String), MsgDef>) -> String {
    let mut deps = Vec::new();
    dependencies(key, all, &mut deps);
    let mut s = all[key].text.trim_end().to_string();
    s.push('\n');
    for d in deps {
        s.push_str(SEPARATOR);
        s.push('\n');
        s.push_str(&format!("MSG: {}/{}\n", d.0, d.1));
        s.push_str(all[&d].text.trim_end());
        s.push('\n');
    }
    s
}

fn read_dir_msgs(dir: &Path, package: &str, all: &mut BTreeMap<(String, String), MsgDef>) {
    println!("cargo:rerun-if-changed={}", dir.display());
    let mut entries: Vec<PathBuf> = std::fs::read_dir(dir)
        .unwrap_or_else(|e| panic!("cannot read {}: {e}", dir.display()))
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "msg"))
        .collect();
    entries.sort();
    for path in entries {
        println!("cargo:rerun-if-changed={}", path.display());
        let name = path.file_stem().unwrap().to_str().unwrap().to_string();
        let text = std::fs::read_to_string(&path).unwrap();
        let def = parse(package, &name, &text, &path);
        all.insert((package.to_string(), name), def);
    }
}

fn main() {
    let root = PathBuf::from(std::env::var("CARGO_MANIFEST_DIR").unwrap());
    let mut all = BTreeMap::new();
    read_dir_msgs(&root.join("msg"), "volcal_msgs", &mut all);
    let deps = root.join("deps");
    println!("cargo:rerun-if-changed={}", deps.display());
    let mut packages: Vec<PathBuf> = std::fs::read_dir(&deps).unwrap().map(|e| e.unwrap().path()).collect();
    packages.sort();
    for p in packages {
        let pkg = p.file_name().unwrap().to_str().unwrap().to_string();
        read_dir_msgs(&p.join("msg"), &pkg, &mut all);
    }

    let mut by_package: BTreeMap<String, Vec<(String, String)>> = BTreeMap::new();
    for k in all.keys() {
        by_package.entry(k.0.clone()).or_default().push(k.clone());
    }
    let mut out = String::new();
    writeln!(out, "// Generated by msgs/build.rs from the .msg files. Do not edit.\n").unwrap();
    for (pkg, keys) in &by_package {
        let (open, close) = if pkg == "volcal_msgs" {
            ("pub mod msg {\n".to_string(), "}\n".to_string())
        } else {
            (
                format!("/// Upstream ROS 2 package `{pkg}` (definitions in `msgs/deps/{pkg}/msg/`).\npub mod {pkg} {{\npub mod msg {{\n"),
                "}\n}\n".to_string(),
            )
        };
        if pkg == "volcal_msgs" {
            writeln!(out, "/// Messages of the `volcal_msgs` package (definitions in `msgs/msg/`).").unwrap();
        }
        out.push_str(&open);
        for key in keys {
            let def = &all[key];
            doc_lines(&mut out, "", &def.doc);
            if !def.doc.is_empty() {
                writeln!(out, "///").unwrap();
            }
            writeln!(out, "/// ROS 2 type `{}/msg/{}`.", def.package, def.name).unwrap();
            writeln!(out, "#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]").unwrap();
            writeln!(out, "pub struct {} {{", def.name).unwrap();
            for f in &def.fields {
                doc_lines(&mut out, "    ", &f.doc);
                writeln!(out, "    pub {}: {},", f.name, rust_type(f)).unwrap();
            }
            writeln!(out, "}}\n").unwrap();
            if !def.constants.is_empty() {
                writeln!(out, "impl {} {{", def.name).unwrap();
                for c in &def.constants {
                    doc_lines(&mut out, "    ", &c.doc);
                    let v = if c.rust_type == "&'static str" { format!("{:?}", c.value) } else { c.value.clone() };
                    writeln!(out, "    pub const {}: {} = {};", c.name, c.rust_type, v).unwrap();
                }
                writeln!(out, "}}\n").unwrap();
            }
            writeln!(out, "impl crate::RosMessage for {} {{", def.name).unwrap();
            writeln!(out, "    const PACKAGE: &'static str = {:?};", def.package).unwrap();
            writeln!(out, "    const NAME: &'static str = {:?};", def.name).unwrap();
            writeln!(out, "    const TYPE_NAME: &'static str = {:?};", format!("{}/msg/{}", def.package, def.name))
                .unwrap();
            writeln!(out, "    const DEFINITION: &'static str = {:?};", def.text).unwrap();
            writeln!(out, "    const SCHEMA: &'static str = {:?};", schema_text(key, &all)).unwrap();
            writeln!(out, "}}\n").unwrap();
        }
        out.push_str(&close);
    }
    writeln!(out, "/// Every message type: `(package/msg/Type, ros2msg schema)`.").unwrap();
    writeln!(out, "pub const ALL_SCHEMAS: &[(&str, &str)] = &[").unwrap();
    for key in all.keys() {
        writeln!(out, "    ({:?}, {:?}),", format!("{}/msg/{}", key.0, key.1), schema_text(key, &all)).unwrap();
    }
    writeln!(out, "];").unwrap();
    let dest = PathBuf::from(std::env::var("OUT_DIR").unwrap()).join("generated.rs");
    std::fs::write(dest, out).unwrap();
}
