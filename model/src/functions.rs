//! Names of the 18 error functions and the 3 squareness errors (ISO 230-1).
//!
//! For axis `K` in {X, Y, Z}: `EXK`, `EYK`, `EZK` are the translation errors of its motion in X,
//! Y, Z (positioning error when the direction is `K` itself, straightness otherwise), and `EAK`,
//! `EBK`, `ECK` its rotation errors about X, Y, Z (roll about its own direction, pitch and yaw
//! about the others). Squareness errors are orientation errors of an axis's mean line, named
//! `E<rotation>0<axis>`: X is the primary reference, Y the secondary, so the model carries `EC0Y`
//! (Y rotated about Z), `EB0Z` (Z about Y) and `EA0Z` (Z about X).
//!
//! The mapping to the patent's `t_k`, `r_k` vectors and to the paper's symbols is in
//! ARCHITECTURE.md.

use crate::axis::Axis;
use nalgebra::Vector3;
use std::fmt;

/// Whether an error function is a translation or a rotation.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub enum Motion {
    Translation,
    Rotation,
}

/// One of the 18 error functions of a three-axis machine.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct ErrorFunction {
    /// The moving axis whose position is the function's argument.
    pub axis: Axis,
    pub motion: Motion,
    /// Direction of the translation, or axis of the rotation.
    pub component: Axis,
}

impl ErrorFunction {
    /// Number of error functions of a three-axis machine.
    pub const COUNT: usize = 18;

    /// The functions in canonical order: for X, Y, Z: `EXK EYK EZK EAK EBK ECK`.
    pub fn all() -> [ErrorFunction; 18] {
        std::array::from_fn(ErrorFunction::from_index)
    }

    /// Canonical index 0..18.
    pub fn index(self) -> usize {
        let m = match self.motion {
            Motion::Translation => 0,
            Motion::Rotation => 3,
        };
        self.axis.index() * 6 + m + self.component.index()
    }

    /// Function with canonical index `i` (0..18).
    pub fn from_index(i: usize) -> ErrorFunction {
        assert!(i < 18, "error function index {i} out of range");
        ErrorFunction {
            axis: Axis::from_index(i / 6),
            motion: if i % 6 < 3 { Motion::Translation } else { Motion::Rotation },
            component: Axis::from_index(i % 3),
        }
    }

    /// ISO 230-1 name, e.g. `EXX`, `EYZ`, `ECY`.
    pub fn name(self) -> String {
        let c = match self.motion {
            Motion::Translation => self.component.letter(),
            Motion::Rotation => self.component.rotary_letter(),
        };
        format!("E{}{}", c, self.axis.letter())
    }

    /// Parses an ISO name such as `EXX` or `ecy`.
    pub fn parse(name: &str) -> Option<ErrorFunction> {
        ErrorFunction::all().into_iter().find(|f| f.name().eq_ignore_ascii_case(name.trim()))
    }

    /// Displacement of the probe per unit of this function's value: its component's unit
    /// vector for a translation, that vector crossed with the lever arm `h` (from the axis's
    /// carriage to the probe, [`crate::topology::Topology::lever_arm`]) for a rotation.
    pub fn unit_response(self, h: &Vector3<f64>) -> Vector3<f64> {
        match self.motion {
            Motion::Translation => self.component.unit(),
            Motion::Rotation => self.component.unit().cross(h),
        }
    }

    /// Positioning error of the axis (translation along itself).
    pub fn is_positioning(self) -> bool {
        self.motion == Motion::Translation && self.component == self.axis
    }

    /// Straightness error (translation across the axis).
    pub fn is_straightness(self) -> bool {
        self.motion == Motion::Translation && self.component != self.axis
    }

    /// Plain description such as "straightness of X in Y" or "roll of Z".
    pub fn describe(self) -> String {
        let a = self.axis.letter();
        let c = self.component.letter();
        match self.motion {
            Motion::Translation if self.axis == self.component => format!("positioning of {a}"),
            Motion::Translation => format!("straightness of {a} in {c}"),
            Motion::Rotation if self.axis == self.component => format!("roll of {a}"),
            Motion::Rotation => format!("rotation of {a} about {c}"),
        }
    }

    /// Unit of the function's values: metres or radians.
    pub fn unit(self) -> &'static str {
        match self.motion {
            Motion::Translation => "m",
            Motion::Rotation => "rad",
        }
    }
}

impl fmt::Display for ErrorFunction {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.name())
    }
}

/// One of the three squareness errors (constant orientation errors of the axes' mean lines).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Squareness {
    /// Y rotated about Z relative to X. Angle between +X and +Y is `90 deg + EC0Y`.
    EC0Y,
    /// Z rotated about Y relative to X. Angle between +X and +Z is `90 deg - EB0Z`.
    EB0Z,
    /// Z rotated about X relative to Y. Angle between +Y and +Z is `90 deg + EA0Z`.
    EA0Z,
}

impl Squareness {
    pub const ALL: [Squareness; 3] = [Squareness::EC0Y, Squareness::EB0Z, Squareness::EA0Z];

    pub fn index(self) -> usize {
        self as usize
    }

    pub fn name(self) -> &'static str {
        match self {
            Squareness::EC0Y => "EC0Y",
            Squareness::EB0Z => "EB0Z",
            Squareness::EA0Z => "EA0Z",
        }
    }

    pub fn parse(name: &str) -> Option<Squareness> {
        Squareness::ALL.into_iter().find(|s| s.name().eq_ignore_ascii_case(name.trim()))
    }

    /// The axis whose orientation the error describes.
    pub fn axis(self) -> Axis {
        match self {
            Squareness::EC0Y => Axis::Y,
            Squareness::EB0Z | Squareness::EA0Z => Axis::Z,
        }
    }

    /// Rotation axis.
    pub fn about(self) -> Axis {
        match self {
            Squareness::EC0Y => Axis::Z,
            Squareness::EB0Z => Axis::Y,
            Squareness::EA0Z => Axis::X,
        }
    }

    /// The straightness error that this squareness would otherwise appear in as a slope.
    pub fn straightness(self) -> ErrorFunction {
        let d = self.direction_per_metre();
        let comp = Axis::ALL.into_iter().find(|c| d[c.index()] != 0.0).unwrap();
        ErrorFunction { axis: self.axis(), motion: Motion::Translation, component: comp }
    }

    /// Error per metre of travel of [`Squareness::axis`] per radian: `about x axis_direction`.
    pub fn direction_per_metre(self) -> Vector3<f64> {
        self.about().unit().cross(&self.axis().unit())
    }

    /// Deviation of the included angle between the two axes from 90 degrees, in radians,
    /// for a value of this error (the sign convention of the paper's Table 2: negative means
    /// the angle is less than 90 degrees).
    pub fn included_angle_deviation(self, value: f64) -> f64 {
        match self {
            Squareness::EC0Y | Squareness::EA0Z => value,
            Squareness::EB0Z => -value,
        }
    }

    pub fn describe(self) -> &'static str {
        match self {
            Squareness::EC0Y => "squareness X-Y",
            Squareness::EB0Z => "squareness X-Z",
            Squareness::EA0Z => "squareness Y-Z",
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_round_trip() {
        for (i, f) in ErrorFunction::all().into_iter().enumerate() {
            assert_eq!(f.index(), i);
            assert_eq!(ErrorFunction::parse(&f.name()), Some(f));
        }
        assert_eq!(ErrorFunction::from_index(0).name(), "EXX");
        assert_eq!(ErrorFunction::from_index(1).name(), "EYX");
        assert_eq!(ErrorFunction::from_index(5).name(), "ECX");
        assert_eq!(ErrorFunction::from_index(17).name(), "ECZ");
        assert_eq!(Squareness::EC0Y.straightness().name(), "EXY");
        assert_eq!(Squareness::EB0Z.straightness().name(), "EXZ");
        assert_eq!(Squareness::EA0Z.straightness().name(), "EYZ");
    }
}
