//! qicp-bridge: see the crate description.
#![warn(missing_docs)]
