//! A refold's objects: for each object touched, the first entry its fold must redo.

use std::collections::BTreeMap;
use std::collections::btree_map;

use super::OrderKey;
use crate::payload::ObjectId;

/// For each object a refold touched, the first order key from which its fold must be redone,
/// in object order. Most insertions touch one object, which is held inline: the in-order path
/// allocates nothing for it. Two or more go into a tree.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct ObjectKeys(Keys);

/// Never `Many` with fewer than two entries (nothing is ever removed), so equal contents have
/// equal forms.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
enum Keys {
    #[default]
    None,
    One(ObjectId, OrderKey),
    Many(BTreeMap<ObjectId, OrderKey>),
}

impl ObjectKeys {
    /// Notes that `object`'s fold must be redone from `key`: its entry becomes the earlier of
    /// the two.
    pub fn lower(&mut self, object: ObjectId, key: OrderKey) {
        match &mut self.0 {
            Keys::None => self.0 = Keys::One(object, key),
            Keys::One(o, k) if *o == object => *k = (*k).min(key),
            Keys::One(o, k) => {
                let map = BTreeMap::from([(*o, *k), (object, key)]);
                self.0 = Keys::Many(map);
            }
            Keys::Many(map) => {
                let k = map.entry(object).or_insert(key);
                *k = (*k).min(key);
            }
        }
    }

    /// The entry of `object`, if the refold touched it.
    pub fn get(&self, object: &ObjectId) -> Option<&OrderKey> {
        match &self.0 {
            Keys::None => None,
            Keys::One(o, k) => (o == object).then_some(k),
            Keys::Many(map) => map.get(object),
        }
    }

    /// True if the refold touched `object`.
    pub fn contains_key(&self, object: &ObjectId) -> bool {
        self.get(object).is_some()
    }

    /// The objects and their entries, in object order.
    pub fn iter(&self) -> Iter<'_> {
        let (one, many) = match &self.0 {
            Keys::None => (None, None),
            Keys::One(o, k) => (Some((o, k)), None),
            Keys::Many(map) => (None, Some(map.iter())),
        };
        one.into_iter().chain(many.into_iter().flatten())
    }

    /// The objects touched, in order.
    pub fn keys(&self) -> impl Iterator<Item = &ObjectId> {
        self.iter().map(|(object, _)| object)
    }

    /// Number of objects touched.
    pub fn len(&self) -> usize {
        match &self.0 {
            Keys::None => 0,
            Keys::One(..) => 1,
            Keys::Many(map) => map.len(),
        }
    }

    /// True if no object was touched.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// The iterator of [`ObjectKeys::iter`].
pub type Iter<'a> = std::iter::Chain<
    std::option::IntoIter<(&'a ObjectId, &'a OrderKey)>,
    std::iter::Flatten<std::option::IntoIter<btree_map::Iter<'a, ObjectId, OrderKey>>>,
>;

impl<'a> IntoIterator for &'a ObjectKeys {
    type Item = (&'a ObjectId, &'a OrderKey);
    type IntoIter = Iter<'a>;

    fn into_iter(self) -> Self::IntoIter {
        self.iter()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::identity::PeerId;

    fn key(lamport: u64) -> OrderKey {
        OrderKey {
            lamport,
            author: PeerId([1; 32]),
            seq: lamport,
        }
    }

    #[test]
    fn object_keys_keep_the_earliest_entry_per_object_in_object_order() {
        // Random objects and keys, against a tree doing the same.
        let mut keys = ObjectKeys::default();
        let mut tree: BTreeMap<ObjectId, OrderKey> = BTreeMap::new();
        assert!(keys.is_empty());
        let mut x: u64 = 7;
        for i in 0..200 {
            x = x.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1);
            // The first dozen stay on one object, so the inline form is exercised too.
            let object = ObjectId(if i < 12 { 5 } else { (x >> 60) % 9 });
            let k = key(x >> 40);
            keys.lower(object, k);
            let e = tree.entry(object).or_insert(k);
            *e = (*e).min(k);
            assert!(keys.iter().eq(tree.iter()), "after {i}");
            assert_eq!(keys.len(), tree.len());
            assert_eq!(keys.get(&object), tree.get(&object));
            assert!(!keys.contains_key(&ObjectId(100)));
        }
        assert!(keys.keys().eq(tree.keys()));
        assert!((&keys).into_iter().eq(tree.iter()));
    }

    #[test]
    fn one_object_is_held_inline_and_equal_contents_compare_equal() {
        let mut a = ObjectKeys::default();
        a.lower(ObjectId(1), key(9));
        a.lower(ObjectId(1), key(4));
        assert!(matches!(a.0, Keys::One(ObjectId(1), k) if k == key(4)));
        let mut b = ObjectKeys::default();
        b.lower(ObjectId(1), key(4));
        assert_eq!(a, b);
        a.lower(ObjectId(2), key(1));
        b.lower(ObjectId(2), key(3));
        assert_ne!(a, b);
        b.lower(ObjectId(2), key(1));
        assert_eq!(a, b);
    }
}
