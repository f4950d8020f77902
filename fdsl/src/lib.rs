//! The sculpt function language.
#![warn(missing_docs)]
