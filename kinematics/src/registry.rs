//! The kinematics a cell's configuration can select, by name with numeric parameters.

use crate::user;
use crate::{BuildError, FiveBar, Gantry, Kinematics, ParamError, Scara, five_bar, gantry, scara};
use alloc::boxed::Box;
use alloc::string::ToString;

/// A kinematics built from a configuration: any type, behind one pointer, shareable between
/// threads.
pub type Boxed = Box<dyn Kinematics + Send + Sync>;

/// Builds one kinematics from its parameters. Names outside the entry's
/// [`params`](Entry::params) and duplicates are refused before it is called.
pub type Builder = fn(&Params<'_>) -> Result<Boxed, ParamError>;

/// One kinematics a configuration may select.
#[derive(Debug)]
pub struct Entry {
    /// The name a configuration's `type = "..."` gives.
    pub name: &'static str,
    /// Every parameter it takes (required or optional): a key beside `type` outside this
    /// list is refused, so a typo cannot pass unnoticed.
    pub params: &'static [&'static str],
    /// Parameters that make a working one (the example cell's): what the crate's tests build
    /// every registered kinematics with, to check it against garbage and that its computing
    /// methods never allocate.
    pub example: &'static [(&'static str, f64)],
    /// Makes it.
    pub build: Builder,
}

impl Entry {
    /// The entry `name`, taking `params`, working with `example`, made by `build`.
    pub const fn new(
        name: &'static str,
        params: &'static [&'static str],
        example: &'static [(&'static str, f64)],
        build: Builder,
    ) -> Self {
        Entry {
            name,
            params,
            example,
            build,
        }
    }

    /// Builds it from its [`example`](Entry::example) parameters.
    ///
    /// # Errors
    ///
    /// What [`build`] says of them (an entry whose example does not build is a mistake the
    /// crate's tests find).
    pub fn build_example(&self) -> Result<Boxed, BuildError> {
        build(self.name, &Params(self.example))
    }
}

/// Every kinematics a cell's configuration can select.
pub const REGISTRY: &[Entry] = &[
    Entry::new("gantry", Gantry::PARAMS, Gantry::EXAMPLE, gantry::build),
    Entry::new("scara", Scara::PARAMS, Scara::EXAMPLE, scara::build),
    Entry::new(
        "five-bar",
        FiveBar::PARAMS,
        FiveBar::EXAMPLE,
        five_bar::build,
    ),
    // Users' own kinematics, one line each: the name a configuration's `type` gives, the
    // parameter names, an example of them, the builder (docs/kinematics.md, "Adding your own
    // kinematics").
    Entry::new(
        "polar",
        user::polar::Polar::PARAMS,
        user::polar::Polar::EXAMPLE,
        user::polar::build,
    ),
];

/// A kinematics' parameters as a configuration gives them: the numeric keys beside
/// `type = "..."` in the `[kinematics]` table, e.g. `[("l1", 200.0), ("l2", 150.0)]`.
#[derive(Clone, Copy, Debug)]
pub struct Params<'a>(pub &'a [(&'a str, f64)]);

impl Params<'_> {
    /// The value of parameter `name`, if given (the first, if given twice).
    pub fn get(&self, name: &str) -> Option<f64> {
        self.0.iter().find(|(n, _)| *n == name).map(|(_, v)| *v)
    }

    /// The value of parameter `name`, which must be given.
    ///
    /// # Errors
    ///
    /// [`ParamError::Missing`] naming it.
    pub fn require(&self, name: &'static str) -> Result<f64, ParamError> {
        self.get(name).ok_or(ParamError::Missing { name })
    }

    /// Refuses a name outside `known`, or one given twice.
    ///
    /// # Errors
    ///
    /// [`ParamError::Unknown`] naming it and the known ones; [`ParamError::Duplicate`].
    pub fn check_names(&self, known: &'static [&'static str]) -> Result<(), ParamError> {
        for (i, (name, _)) in self.0.iter().enumerate() {
            if !known.contains(name) {
                return Err(ParamError::Unknown {
                    name: name.to_string(),
                    known,
                });
            }
            if self.0.iter().take(i).any(|(earlier, _)| earlier == name) {
                return Err(ParamError::Duplicate {
                    name: name.to_string(),
                });
            }
        }
        Ok(())
    }
}

/// The kinematics of type `type_name` with `params`, as a cell's configuration selects it:
/// the [`REGISTRY`] entry of that name, its parameter names checked, then built (which
/// validates the values).
///
/// Setup, not the cycle: it allocates the `Box`.
///
/// # Errors
///
/// [`BuildError::UnknownType`] (its message lists the known types);
/// [`BuildError::Params`] with the kinematics' [`ParamError`].
pub fn build(type_name: &str, params: &Params<'_>) -> Result<Boxed, BuildError> {
    let Some(entry) = REGISTRY.iter().find(|entry| entry.name == type_name) else {
        return Err(BuildError::UnknownType {
            name: type_name.to_string(),
        });
    };
    params
        .check_names(entry.params)
        .and_then(|()| (entry.build)(params))
        .map_err(|error| BuildError::Params {
            kinematics: entry.name,
            error,
        })
}
