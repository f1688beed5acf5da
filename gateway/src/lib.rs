//! The cell's gateway to a line of cells (issue 20, under way: no process yet): what
//! crosses the network and how a command from it is judged, apart from the transport.
//!
//! - [`keys`]: the versioned key space, everything of a cell under `rtc/v1/<cell>/`;
//! - [`command`]: what a remote client may ask a cell, as the network's JSON, and the
//!   control-plane request each becomes;
//! - [`auth`]: who may ask it: the line's users (a viewer may read, an operator may also
//!   command), each command signed with its user's secret (HMAC-SHA256), fresh and never
//!   replayed; a refusal says why, where the transport's own access control would be silent.
//!
//! Nothing real-time crosses the network: the gateway is a client of the cell's control
//! channel like `supervisor pause`, under the cell's own user.

pub mod auth;
pub mod command;
pub mod keys;
