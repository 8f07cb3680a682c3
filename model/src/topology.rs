//! Axis stacking of a Cartesian machine, written as a topology string.
//!
//! The string lists the frame `F` and the three axes in the order of the kinematic chain from
//! the workpiece to the tool, as in the paper's `W-F-Y-X-Z-T`: `FXYZ` (the patent's example: X
//! carries Y, which carries Z), `FYXZ` (bridge CMM: Y carries X carries Z), `XFYZ` (a table moving
//! in X carries the workpiece; Y and Z carry the tool).
//!
//! All error functions are those of the relative motion of the tool with respect to the
//! workpiece (ISO 230-1). With that convention the volumetric error depends only on the order of
//! the axes along the chain, not on which side of the frame they sit: an axis's rotation acts on
//! the lever arm from that axis to the tool, i.e. the coordinates of every axis between it and the
//! tool plus the probe offset (patent eq. 7). For axes that carry the workpiece the functions
//! therefore have the opposite sign of the table carriage's own motion.

use crate::axis::Axis;
use nalgebra::{Point3, Vector3};
use std::fmt;

/// Error parsing a topology string.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("unknown topology {text:?}: {reason} (expected the frame F and the axes X, Y, Z each once, in chain order from workpiece to tool, e.g. FXYZ, FYXZ, XFYZ, YFXZ)")]
pub struct TopologyError {
    pub text: String,
    pub reason: String,
}

/// The axis stacking of a three-axis Cartesian machine.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub struct Topology {
    /// Axes in chain order from the workpiece to the tool, the frame removed.
    chain: [Axis; 3],
    /// Position of `F` in the string, i.e. how many axes carry the workpiece.
    table_axes: usize,
}

impl Topology {
    /// Parses a topology string such as `FXYZ`.
    pub fn parse(text: &str) -> Result<Topology, TopologyError> {
        let err = |reason: &str| TopologyError { text: text.to_string(), reason: reason.to_string() };
        let t = text.trim();
        if t.chars().count() != 4 {
            return Err(err("it must have exactly four letters"));
        }
        let mut chain = Vec::with_capacity(3);
        let mut frame = None;
        for (i, c) in t.chars().enumerate() {
            if c.eq_ignore_ascii_case(&'F') {
                if frame.is_some() {
                    return Err(err("F appears twice"));
                }
                frame = Some(i);
            } else if let Some(a) = Axis::from_letter(c) {
                if chain.contains(&a) {
                    return Err(err(&format!("axis {} appears twice", a.letter())));
                }
                chain.push(a);
            } else {
                return Err(err(&format!("letter {c:?} is neither F nor an axis")));
            }
        }
        let table_axes = frame.ok_or_else(|| err("the frame F is missing"))?;
        Ok(Topology { chain: [chain[0], chain[1], chain[2]], table_axes })
    }

    /// Axes in chain order from the workpiece to the tool.
    pub fn chain(&self) -> [Axis; 3] {
        self.chain
    }

    /// Whether `a` carries the workpiece (sits before `F` in the string).
    pub fn is_table_axis(&self, a: Axis) -> bool {
        self.position(a) < self.table_axes
    }

    /// Position of an axis in the chain (0 = nearest the workpiece).
    pub fn position(&self, a: Axis) -> usize {
        self.chain.iter().position(|&c| c == a).expect("every axis is in the chain")
    }

    /// The axis nearest the tool: its rotations act only through the probe offset.
    pub fn last_axis(&self) -> Axis {
        self.chain[2]
    }

    /// Lever arm of the rotation errors of axis `a` (patent eq. 7, generalised): the coordinate
    /// vectors of all axes between `a` and the tool, plus the probe offset `p`.
    pub fn lever_arm(&self, a: Axis, x: &Point3<f64>, p: &Vector3<f64>) -> Vector3<f64> {
        let mut h = *p;
        for &b in &self.chain[self.position(a) + 1..] {
            h[b.index()] += x[b.index()];
        }
        h
    }

    /// Axes carried by `a` (between `a` and the tool), in chain order.
    pub fn carried_by(&self, a: Axis) -> &[Axis] {
        &self.chain[self.position(a) + 1..]
    }
}

impl fmt::Display for Topology {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for (i, a) in self.chain.iter().enumerate() {
            if i == self.table_axes {
                write!(f, "F")?;
            }
            write!(f, "{}", a.letter())?;
        }
        if self.table_axes == 3 {
            write!(f, "F")?;
        }
        Ok(())
    }
}

impl std::str::FromStr for Topology {
    type Err = TopologyError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Topology::parse(s)
    }
}

#[cfg(feature = "serde")]
impl serde::Serialize for Topology {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(&self.to_string())
    }
}

#[cfg(feature = "serde")]
impl<'de> serde::Deserialize<'de> for Topology {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let s = String::deserialize(d)?;
        Topology::parse(&s).map_err(serde::de::Error::custom)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_and_prints() {
        for s in ["FXYZ", "FYXZ", "XFYZ", "YFXZ", "XYFZ", "XYZF"] {
            assert_eq!(Topology::parse(s).unwrap().to_string(), s);
        }
        assert!(Topology::parse("FXXZ").is_err());
        assert!(Topology::parse("XYZ").is_err());
        assert!(Topology::parse("FXYQ").is_err());
        assert!(Topology::parse("XYZW").is_err());
    }

    #[test]
    fn patent_lever_arms() {
        let t = Topology::parse("FXYZ").unwrap();
        let x = Point3::new(1.0, 2.0, 3.0);
        let p = Vector3::new(0.1, 0.2, 0.3);
        assert_eq!(t.lever_arm(Axis::X, &x, &p), Vector3::new(0.1, 2.2, 3.3));
        assert_eq!(t.lever_arm(Axis::Y, &x, &p), Vector3::new(0.1, 0.2, 3.3));
        assert_eq!(t.lever_arm(Axis::Z, &x, &p), p);
        let b = Topology::parse("FYXZ").unwrap();
        assert_eq!(b.lever_arm(Axis::Y, &x, &p), Vector3::new(1.1, 0.2, 3.3));
        assert!(Topology::parse("XFYZ").unwrap().is_table_axis(Axis::X));
    }
}
