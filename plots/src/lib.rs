//! The pictures of `qicp run` (PNG), in the style of the paper's figures:
//!
//! - [`occupancy_map`]: every scan drawn at a matcher's poses into a 5 cm occupancy grid, the
//!   estimated path and the true one on top (paper Figs. 3, 5, 6);
//! - [`trajectories`]: every matcher's path with the truth and raw odometry;
//! - [`per_scan`]: a value per scan, one panel per matcher family, a series drawn in front of
//!   another and each series' mean as a thick line (paper Fig. 4).
//!
//! Text uses DejaVu Sans, embedded from the `dejavu` crate and rasterised by `ab_glyph`: no
//! system font or fontconfig is needed.

#![warn(missing_docs)]

use plotters::coord::Shift;
use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;
use qicp_core::{BeamStatus, Pose2, Scan};
use std::path::Path;
use thiserror::Error;

/// Why a picture could not be drawn.
#[derive(Debug, Error)]
pub enum PlotError {
    /// The drawing backend failed (usually writing the file).
    #[error("drawing {path}: {message}")]
    Draw {
        /// The picture.
        path: String,
        /// What plotters reported.
        message: String,
    },
    /// There is nothing to draw.
    #[error("drawing {path}: {why}")]
    Empty {
        /// The picture.
        path: String,
        /// What is missing.
        why: &'static str,
    },
}

/// Side of an occupancy-grid cell (m).
pub const MAP_CELL_M: f64 = 0.05;
/// No-return beams mark free space up to this range (m), at most the laser's maximum.
pub const FREE_SPACE_MAX_M: f64 = 20.0;
/// Longest side of a map's plotting area (pixels): larger maps pool several cells into a
/// pixel, smaller ones draw a cell as a block of up to [`MAP_MAX_ZOOM`] pixels.
pub const MAP_PIXELS: f64 = 1400.0;
/// Most pixels per cell side of a small map.
pub const MAP_MAX_ZOOM: f64 = 3.0;

pub(crate) const FONT: &str = "sans-serif";

/// Colours of the series, in report order (a colour-blind-safe palette, Wong 2011).
pub const PALETTE: [RGBColor; 7] = [
    RGBColor(213, 94, 0),    // vermillion
    RGBColor(0, 114, 178),   // blue
    RGBColor(0, 158, 115),   // bluish green
    RGBColor(230, 159, 0),   // orange
    RGBColor(204, 121, 167), // reddish purple
    RGBColor(86, 180, 233),  // sky blue
    RGBColor(240, 228, 66),  // yellow
];
/// Colour of the true path.
pub const TRUTH_COLOR: RGBColor = RGBColor(0, 0, 0);
/// Colour of the raw odometry path.
pub const ODOMETRY_COLOR: RGBColor = RGBColor(150, 150, 150);

/// Registers the embedded font with plotters (once per process).
pub(crate) fn register_fonts() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        for family in ["sans-serif", "serif", "monospace"] {
            // The bytes are a valid TrueType font; a failure would leave text undrawn, not
            // break the picture.
            let _ =
                plotters::style::register_font(family, FontStyle::Normal, dejavu::sans::regular());
            let _ = plotters::style::register_font(family, FontStyle::Bold, dejavu::sans::bold());
        }
    });
}

pub(crate) fn draw_err(path: &Path) -> impl Fn(&dyn std::fmt::Display) -> PlotError + '_ {
    move |e| PlotError::Draw {
        path: path.display().to_string(),
        message: e.to_string(),
    }
}

/// `?` for plotters results: turns any plotters error into [`PlotError::Draw`].
macro_rules! tri {
    ($path:expr, $e:expr) => {
        $e.map_err(|e| draw_err($path)(&e))?
    };
}

// The pictures, after the macro they use (macros are in scope from their definition on).
mod extent;
mod map;
mod paths;
mod per_scan;

pub use extent::*;
pub use map::*;
pub use paths::*;
pub use per_scan::*;
