//! The control plane's types against what they say: a failure's words (`failure`), the
//! figures' data (`figures`), the status document (`status`). Here rather than in each module
//! (`#[cfg(test)]`), so that the test build uses the library as built instead of compiling it
//! again (5.9 s of CPU in a clean test build).

mod failure;
mod figures;
mod status;
