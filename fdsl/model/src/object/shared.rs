//! A part of a description that copies of it share until one of them changes it.
//!
//! Most objects leave their physics and much of their appearance at the defaults, and a
//! scene copies an object's description on every property it sets. Inline, those two parts
//! are about 1 KB of every description and of every copy; shared, a default costs one pointer
//! and a copy costs a count.

use std::fmt;
use std::ops::{Deref, DerefMut};
use std::sync::{Arc, LazyLock};

use serde::{Deserialize, Deserializer, Serialize, Serializer};

use super::{Appearance, Physics};

/// A value shared between copies and copied when changed through one of them (copy on
/// write): it reads as `&T`, and writing through it copies the value first if another copy
/// holds it too. Its default is one value per process that every default shares, and a
/// decoded value equal to the default shares it too.
#[derive(Clone, PartialEq)]
pub struct Shared<T>(Arc<T>);

impl<T> Shared<T> {
    /// Whether `a` and `b` hold the same value, not merely equal ones.
    pub fn ptr_eq(a: &Shared<T>, b: &Shared<T>) -> bool {
        Arc::ptr_eq(&a.0, &b.0)
    }
}

impl<T> Deref for Shared<T> {
    type Target = T;

    fn deref(&self) -> &T {
        &self.0
    }
}

impl<T: Clone> DerefMut for Shared<T> {
    fn deref_mut(&mut self) -> &mut T {
        Arc::make_mut(&mut self.0)
    }
}

impl<T> From<T> for Shared<T> {
    fn from(value: T) -> Shared<T> {
        Shared(Arc::new(value))
    }
}

impl<T: fmt::Debug> fmt::Debug for Shared<T> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        self.0.fmt(f)
    }
}

impl<T: Serialize> Serialize for Shared<T> {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        self.0.serialize(serializer)
    }
}

impl<'de, T> Deserialize<'de> for Shared<T>
where
    T: Deserialize<'de> + Default + PartialEq,
    Shared<T>: Default,
{
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Shared<T>, D::Error> {
        let value = T::deserialize(deserializer)?;
        Ok(if value == T::default() {
            Shared::default()
        } else {
            Shared::from(value)
        })
    }
}

static DEFAULT_APPEARANCE: LazyLock<Shared<Appearance>> =
    LazyLock::new(|| Shared::from(Appearance::default()));
static DEFAULT_PHYSICS: LazyLock<Shared<Physics>> =
    LazyLock::new(|| Shared::from(Physics::default()));

impl Default for Shared<Appearance> {
    fn default() -> Shared<Appearance> {
        DEFAULT_APPEARANCE.clone()
    }
}

impl Default for Shared<Physics> {
    fn default() -> Shared<Physics> {
        DEFAULT_PHYSICS.clone()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::object::{Formula, Property};

    #[test]
    fn defaults_share_one_value_and_a_change_copies_it() {
        let (a, mut b) = (Shared::<Physics>::default(), Shared::<Physics>::default());
        assert!(Shared::ptr_eq(&a, &b));
        b.density = Some(Property::new(Formula::new("1").unwrap()));
        assert!(!Shared::ptr_eq(&a, &b));
        assert_eq!(*a, Physics::default(), "the shared default is untouched");
        let c = b.clone();
        assert!(Shared::ptr_eq(&b, &c));
    }

    #[test]
    fn a_decoded_default_shares_the_default_and_anything_else_stands_alone() {
        let bytes = postcard::to_allocvec(&Shared::<Appearance>::default()).unwrap();
        let decoded: Shared<Appearance> = postcard::from_bytes(&bytes).unwrap();
        assert!(Shared::ptr_eq(&decoded, &Shared::default()));

        let changed = Shared::from(Appearance {
            shininess: Some(Formula::new("0.5").unwrap()),
            ..Appearance::default()
        });
        let bytes = postcard::to_allocvec(&changed).unwrap();
        let decoded: Shared<Appearance> = postcard::from_bytes(&bytes).unwrap();
        assert_eq!(decoded, changed);
        assert!(!Shared::ptr_eq(&decoded, &Shared::default()));
        assert_eq!(
            bytes,
            postcard::to_allocvec(&*changed).unwrap(),
            "encoded as its value"
        );
    }
}
