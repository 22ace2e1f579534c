//! The HTML report of a synthesis run: `report.html`, one self-contained page (inline SVG and CSS)
//! rendered from the plot-ready [`data::ReportData`]. `data` (owned by the lead) defines the input;
//! `planar` the 2-D clipping, `plots` the SVG plots, `format` the number and text formatting, and `html`
//! the page itself.

pub mod after_goal;
pub mod data;
pub mod format;
pub mod html;
pub mod hybrid;
pub mod optimization;
pub mod planar;
pub mod plots;
mod present;
pub mod pwa;
pub mod temporal;

pub use after_goal::after_goal_line;
pub use html::{render_html, verdict, write_report, Verdict};
pub use present::report_data;
