//! qicp-sim: see the crate description.
#![warn(missing_docs)]
