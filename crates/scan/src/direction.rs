use serde::{Deserialize, Serialize};

/// A direction of tip motion in display orientation (row 0 at the top, column 0 at the left).
///
/// `Right` = increasing column, `Down` = increasing row (the DHCT paper's "forward" directions);
/// `Left` and `Up` are the reversed ones.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ScanDirection {
    /// Increasing column (left to right).
    Right,
    /// Decreasing column (right to left).
    Left,
    /// Increasing row (top to bottom).
    Down,
    /// Decreasing row (bottom to top).
    Up,
}

/// An image axis: columns (x, horizontal) or rows (y, vertical).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Axis {
    /// Along a row, i.e. the column index (x).
    Horizontal,
    /// Along a column, i.e. the row index (y).
    Vertical,
}

impl ScanDirection {
    /// The axis this direction moves along.
    pub fn axis(self) -> Axis {
        match self {
            ScanDirection::Right | ScanDirection::Left => Axis::Horizontal,
            ScanDirection::Down | ScanDirection::Up => Axis::Vertical,
        }
    }

    /// True for `Right` and `Down` (index increases with time).
    pub fn is_increasing(self) -> bool {
        matches!(self, ScanDirection::Right | ScanDirection::Down)
    }

    /// The opposite direction (the retrace of a trace).
    pub fn reversed(self) -> ScanDirection {
        match self {
            ScanDirection::Right => ScanDirection::Left,
            ScanDirection::Left => ScanDirection::Right,
            ScanDirection::Down => ScanDirection::Up,
            ScanDirection::Up => ScanDirection::Down,
        }
    }

    /// Parses the names used by the paper and by instrument headers:
    /// right/left/down/up, case-insensitive.
    pub fn parse(name: &str) -> Option<ScanDirection> {
        match name.trim().to_ascii_lowercase().as_str() {
            "right" => Some(ScanDirection::Right),
            "left" => Some(ScanDirection::Left),
            "down" => Some(ScanDirection::Down),
            "up" => Some(ScanDirection::Up),
            _ => None,
        }
    }
}

/// Which line of a line pair an image comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ScanPass {
    /// The first line of each pair (often called "forward").
    Trace,
    /// The line scanned back after the trace (often called "backward").
    Retrace,
}

impl ScanPass {
    /// Both passes, trace first.
    pub const BOTH: [ScanPass; 2] = [ScanPass::Trace, ScanPass::Retrace];

    /// `"trace"` or `"retrace"` (file names, channel names, messages).
    pub fn name(self) -> &'static str {
        match self {
            ScanPass::Trace => "trace",
            ScanPass::Retrace => "retrace",
        }
    }

    /// The pass whose [`ScanPass::name`] is `name`, if any.
    pub fn from_name(name: &str) -> Option<ScanPass> {
        ScanPass::BOTH.into_iter().find(|p| p.name() == name)
    }
}

impl std::fmt::Display for ScanPass {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}
