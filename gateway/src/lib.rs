//! The cell's gateway to a line of cells (`docs/network.md`): what crosses the network, how
//! a command from it is judged, and the Zenoh session that carries it.
//!
//! - [`keys`]: the versioned key space, everything of a cell under `rtc/v1/<cell>/`;
//! - [`command`]: what a remote client may ask a cell, as the network's JSON, and the
//!   control-plane request each becomes;
//! - [`auth`]: who may ask it: the line's users (a viewer may read, an operator may also
//!   command), each command signed with its user's secret (HMAC-SHA256), fresh and never
//!   replayed; a refusal says why, where the transport's own access control would be silent;
//! - [`budget`]: at most so many log lines of a flood of commands, the rest counted;
//! - [`link`]: a Zenoh session from a `[network]` section or a control room's line file;
//! - [`wire`]: the status, events and answers as the network carries them;
//! - [`ros2`]: the cell's joint states as ROS 2 reads them through rmw_zenoh.
//!
//! Nothing real-time crosses the network: the gateway is a client of the cell's control
//! channel like `supervisor pause`, under the cell's own user.

pub mod auth;
pub mod budget;
pub mod command;
pub mod keys;
pub mod link;
pub mod ros2;
pub mod wire;
