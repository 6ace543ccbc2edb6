use serde::{Deserialize, Serialize};

use crate::{GeometryError, ImageChannel, ScanGeometry, ScanPass};

/// The trace and/or retrace image of one channel, sharing one [`ScanGeometry`].
///
/// Both images are in display orientation. At least one is present; usually the trace.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "RawScanPair", into = "RawScanPair")]
pub struct ScanPair {
    geometry: ScanGeometry,
    trace: Option<ImageChannel>,
    retrace: Option<ImageChannel>,
}

impl ScanPair {
    /// A pair of a trace and an optional retrace; both must match the geometry's size.
    pub fn new(
        geometry: ScanGeometry,
        trace: ImageChannel,
        retrace: Option<ImageChannel>,
    ) -> Result<ScanPair, GeometryError> {
        Self::from_parts(geometry, Some(trace), retrace)
    }

    /// A pair of which only the retrace was recorded.
    pub fn retrace_only(
        geometry: ScanGeometry,
        retrace: ImageChannel,
    ) -> Result<ScanPair, GeometryError> {
        Self::from_parts(geometry, None, Some(retrace))
    }

    /// A pair from optional trace and retrace; at least one must be given.
    pub fn from_parts(
        geometry: ScanGeometry,
        trace: Option<ImageChannel>,
        retrace: Option<ImageChannel>,
    ) -> Result<ScanPair, GeometryError> {
        if trace.is_none() && retrace.is_none() {
            return Err(GeometryError::NoImages);
        }
        for (image, channel) in [("trace", &trace), ("retrace", &retrace)] {
            if let Some(channel) = channel
                && (channel.rows() != geometry.rows() || channel.columns() != geometry.columns())
            {
                return Err(GeometryError::ShapeMismatch {
                    image,
                    columns: channel.columns(),
                    rows: channel.rows(),
                    geometry_columns: geometry.columns(),
                    geometry_rows: geometry.rows(),
                });
            }
        }
        Ok(ScanPair {
            geometry,
            trace,
            retrace,
        })
    }

    /// The shared scan geometry.
    pub fn geometry(&self) -> &ScanGeometry {
        &self.geometry
    }

    /// The trace image, if recorded.
    pub fn trace(&self) -> Option<&ImageChannel> {
        self.trace.as_ref()
    }

    /// The retrace image, if recorded.
    pub fn retrace(&self) -> Option<&ImageChannel> {
        self.retrace.as_ref()
    }

    /// The image of `pass`, if recorded.
    pub fn image(&self, pass: ScanPass) -> Option<&ImageChannel> {
        match pass {
            ScanPass::Trace => self.trace(),
            ScanPass::Retrace => self.retrace(),
        }
    }

    /// The recorded images with their pass, trace first.
    pub fn images(&self) -> impl Iterator<Item = (ScanPass, &ImageChannel)> {
        ScanPass::BOTH
            .into_iter()
            .filter_map(move |pass| self.image(pass).map(|image| (pass, image)))
    }

    /// Channel name (of the trace, or of the retrace when there is no trace).
    pub fn name(&self) -> &str {
        self.images()
            .next()
            .map(|(_, c)| c.name.as_str())
            .unwrap_or("")
    }

    /// Splits the pair into its parts.
    pub fn into_parts(self) -> (ScanGeometry, Option<ImageChannel>, Option<ImageChannel>) {
        (self.geometry, self.trace, self.retrace)
    }
}

#[derive(Serialize, Deserialize)]
struct RawScanPair {
    geometry: ScanGeometry,
    trace: Option<ImageChannel>,
    retrace: Option<ImageChannel>,
}

impl TryFrom<RawScanPair> for ScanPair {
    type Error = GeometryError;
    fn try_from(raw: RawScanPair) -> Result<Self, Self::Error> {
        ScanPair::from_parts(raw.geometry, raw.trace, raw.retrace)
    }
}

impl From<ScanPair> for RawScanPair {
    fn from(p: ScanPair) -> Self {
        RawScanPair {
            geometry: p.geometry,
            trace: p.trace,
            retrace: p.retrace,
        }
    }
}
