//! qicp-matchers: see the crate description.
#![warn(missing_docs)]
