//! Typed YOLO11 scale presets (`n`, `s`) and the channel / repeat rules that apply them.
//!
//! ultralytics describes the network once at full width (`cfg/models/11/yolo11-seg.yaml`) and
//! scales it with `[depth, width, max_channels]`; `parse_model` rounds every width up to a
//! multiple of 8 and every repeat count to `max(round(n · depth), 1)`. We keep that rule so
//! that the parameter counts match the reference, plus an extra width multiplier for
//! scene-sized models.

use serde::{Deserialize, Serialize};

/// A YOLO11 model scale.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Scale {
    N,
    S,
}

impl Scale {
    /// `[depth, width, max_channels]` from `yolo11-seg.yaml`.
    pub fn factors(self) -> (f64, f64, usize) {
        match self {
            Scale::N => (0.50, 0.25, 1024),
            Scale::S => (0.50, 0.50, 1024),
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            Scale::N => "n",
            Scale::S => "s",
        }
    }
}

impl std::str::FromStr for Scale {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "n" | "N" => Ok(Scale::N),
            "s" | "S" => Ok(Scale::S),
            other => Err(format!(
                "unknown YOLO scale '{other}', expected one of: n, s"
            )),
        }
    }
}

/// `ceil(x / 8) · 8`, ultralytics' `make_divisible(x, 8)`.
pub fn ceil8(x: f64) -> usize {
    ((x / 8.0).ceil() as usize * 8).max(8)
}

/// Channel and repeat rule for one scale with an extra width multiplier.
#[derive(Debug, Clone, Copy)]
pub struct Scaler {
    pub depth: f64,
    pub width: f64,
    pub max_channels: usize,
}

impl Scaler {
    pub fn new(scale: Scale, width_mult: f64) -> Self {
        assert!(
            width_mult.is_finite() && width_mult > 0.0,
            "width multiplier must be finite and > 0, got {width_mult}"
        );
        let (depth, width, max_channels) = scale.factors();
        Self {
            depth,
            width: width * width_mult,
            max_channels,
        }
    }

    /// Scaled channel count of a full-width layer with `c` channels.
    pub fn ch(&self, c: usize) -> usize {
        ceil8(c.min(self.max_channels) as f64 * self.width)
    }

    /// Scaled repeat count of a full-depth layer with `n` repeats.
    pub fn n(&self, n: usize) -> usize {
        ((n as f64 * self.depth).round() as usize).max(1)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn channels_follow_parse_model() {
        let n = Scaler::new(Scale::N, 1.0);
        assert_eq!([n.ch(64), n.ch(256), n.ch(1024)], [16, 64, 256]);
        assert_eq!(n.n(2), 1);
        let s = Scaler::new(Scale::S, 1.0);
        assert_eq!([s.ch(64), s.ch(512), s.ch(1024)], [32, 256, 512]);
        // Narrow scene models still round up to multiples of 8.
        let tiny = Scaler::new(Scale::N, 0.5);
        assert_eq!([tiny.ch(64), tiny.ch(128), tiny.ch(1024)], [8, 16, 128]);
        assert_eq!(ceil8(9.0), 16);
    }

    #[test]
    fn parses_names() {
        assert_eq!("n".parse::<Scale>(), Ok(Scale::N));
        assert!("m"
            .parse::<Scale>()
            .unwrap_err()
            .contains("expected one of: n, s"));
    }

    #[test]
    #[should_panic(expected = "width multiplier must be finite and > 0, got -1")]
    fn rejects_bad_width() {
        Scaler::new(Scale::N, -1.0);
    }
}
