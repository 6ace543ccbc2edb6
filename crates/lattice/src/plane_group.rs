use serde::{Deserialize, Serialize};

/// The 17 plane (wallpaper) groups, in International (Hermann–Mauguin) short notation.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(try_from = "String", into = "String")]
pub enum PlaneGroup {
    /// Oblique, no symmetry but translations.
    P1,
    /// Oblique, two-fold rotations.
    P2,
    /// Rectangular, parallel mirrors.
    Pm,
    /// Rectangular, parallel glides.
    Pg,
    /// Centred rectangular, mirrors (conventional cell, centring (½, ½)).
    Cm,
    /// Rectangular, two perpendicular mirror sets.
    P2mm,
    /// Rectangular, mirrors and perpendicular glides.
    P2mg,
    /// Rectangular, two perpendicular glide sets.
    P2gg,
    /// Centred rectangular, two perpendicular mirror sets (conventional cell).
    C2mm,
    /// Square, four-fold rotations.
    P4,
    /// Square, four-fold rotations and mirrors through them.
    P4mm,
    /// Square, four-fold rotations, mirrors off them.
    P4gm,
    /// Hexagonal, three-fold rotations.
    P3,
    /// Hexagonal, three-fold rotations, every three-fold axis on mirrors.
    P3m1,
    /// Hexagonal, three-fold rotations, some three-fold axes off the mirrors.
    P31m,
    /// Hexagonal, six-fold rotations.
    P6,
    /// Hexagonal, six-fold rotations and mirrors.
    P6mm,
}

impl PlaneGroup {
    /// All 17 groups, ordered by crystal system.
    pub const ALL: [PlaneGroup; 17] = [
        PlaneGroup::P1,
        PlaneGroup::P2,
        PlaneGroup::Pm,
        PlaneGroup::Pg,
        PlaneGroup::Cm,
        PlaneGroup::P2mm,
        PlaneGroup::P2mg,
        PlaneGroup::P2gg,
        PlaneGroup::C2mm,
        PlaneGroup::P4,
        PlaneGroup::P4mm,
        PlaneGroup::P4gm,
        PlaneGroup::P3,
        PlaneGroup::P3m1,
        PlaneGroup::P31m,
        PlaneGroup::P6,
        PlaneGroup::P6mm,
    ];

    /// The short symbol, e.g. "p3m1".
    pub fn symbol(self) -> &'static str {
        match self {
            PlaneGroup::P1 => "p1",
            PlaneGroup::P2 => "p2",
            PlaneGroup::Pm => "pm",
            PlaneGroup::Pg => "pg",
            PlaneGroup::Cm => "cm",
            PlaneGroup::P2mm => "p2mm",
            PlaneGroup::P2mg => "p2mg",
            PlaneGroup::P2gg => "p2gg",
            PlaneGroup::C2mm => "c2mm",
            PlaneGroup::P4 => "p4",
            PlaneGroup::P4mm => "p4mm",
            PlaneGroup::P4gm => "p4gm",
            PlaneGroup::P3 => "p3",
            PlaneGroup::P3m1 => "p3m1",
            PlaneGroup::P31m => "p31m",
            PlaneGroup::P6 => "p6",
            PlaneGroup::P6mm => "p6mm",
        }
    }

    /// Number of symmetry operations per conventional cell (for cm and c2mm this counts the
    /// centring translation: twice the point-group order).
    pub fn order(self) -> usize {
        match self {
            PlaneGroup::P1 => 1,
            PlaneGroup::P2 | PlaneGroup::Pm | PlaneGroup::Pg => 2,
            PlaneGroup::P3 => 3,
            PlaneGroup::Cm
            | PlaneGroup::P2mm
            | PlaneGroup::P2mg
            | PlaneGroup::P2gg
            | PlaneGroup::P4 => 4,
            PlaneGroup::P3m1 | PlaneGroup::P31m | PlaneGroup::P6 => 6,
            PlaneGroup::C2mm | PlaneGroup::P4mm | PlaneGroup::P4gm => 8,
            PlaneGroup::P6mm => 12,
        }
    }
}

impl std::fmt::Display for PlaneGroup {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.symbol())
    }
}

/// A plane-group symbol that is not one of the 17 wallpaper groups.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("unknown plane group '{0}' (use one of the 17 wallpaper groups, e.g. p3m1, p6mm, p4mm)")]
pub struct UnknownPlaneGroup(pub String);

impl std::str::FromStr for PlaneGroup {
    type Err = UnknownPlaneGroup;
    fn from_str(text: &str) -> Result<Self, Self::Err> {
        let wanted = text.trim().to_ascii_lowercase();
        PlaneGroup::ALL
            .into_iter()
            .find(|g| g.symbol() == wanted)
            .ok_or_else(|| UnknownPlaneGroup(text.to_string()))
    }
}

impl TryFrom<String> for PlaneGroup {
    type Error = UnknownPlaneGroup;
    fn try_from(text: String) -> Result<Self, Self::Error> {
        text.parse()
    }
}

impl From<PlaneGroup> for String {
    fn from(group: PlaneGroup) -> String {
        group.symbol().to_string()
    }
}
