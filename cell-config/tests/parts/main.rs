//! The configuration's checks, each against the error a user reads: the cell file
//! (`config`), `[network]` (`network`), the derived stability limits (`stability`). Here
//! rather than in each module (`#[cfg(test)]`), so that the test build uses the library as
//! built instead of compiling it again (10.3 s of CPU in a clean test build).

mod config;
mod network;
mod stability;
