//! Sequences with a length cap, enforced while they are read.
//!
//! A typed parse allocates as it reads: a 16 MiB body of `0,0,0,…` is eight
//! million numbers, 64 MB as `Vec<f64>` before any validation could say the
//! prior has 56 weights. Every sequence whose legitimate length is small
//! (weights, covariance rows, joints, obstacles, hull points) is read
//! through [`AtMost`], which refuses the first element beyond its cap, so
//! the memory a body can make is bounded by what its caps allow, not by
//! its size.

use serde::de::{DeserializeSeed, Deserializer, SeqAccess, Visitor};
use std::fmt;
use std::marker::PhantomData;

/// Reads a JSON array of at most `max` items, each through `item`.
#[derive(Clone, Copy, Debug)]
pub struct AtMost<S> {
    /// Largest accepted length.
    pub max: usize,
    /// The seed each item is read with.
    pub item: S,
}

impl<T> AtMost<PhantomData<T>> {
    /// At most `max` items of a plain `Deserialize` type.
    pub fn items(max: usize) -> Self {
        AtMost {
            max,
            item: PhantomData,
        }
    }
}

impl<'de, S: DeserializeSeed<'de> + Clone> DeserializeSeed<'de> for AtMost<S> {
    type Value = Vec<S::Value>;

    fn deserialize<D: Deserializer<'de>>(self, deserializer: D) -> Result<Self::Value, D::Error> {
        deserializer.deserialize_seq(self)
    }
}

impl<'de, S: DeserializeSeed<'de> + Clone> Visitor<'de> for AtMost<S> {
    type Value = Vec<S::Value>;

    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "an array of at most {} items", self.max)
    }

    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Self::Value, A::Error> {
        let mut items = Vec::with_capacity(seq.size_hint().unwrap_or(0).min(self.max).min(1024));
        while let Some(item) = seq.next_element_seed(self.item.clone())? {
            if items.len() == self.max {
                return Err(serde::de::Error::custom(format!(
                    "too long: at most {} items are accepted",
                    self.max
                )));
            }
            items.push(item);
        }
        Ok(items)
    }
}

/// `#[serde(deserialize_with = "vec_at_most::<_, _, N>")]`: a `Vec<T>` of
/// at most `N` items.
pub fn vec_at_most<'de, D, T, const N: usize>(deserializer: D) -> Result<Vec<T>, D::Error>
where
    D: Deserializer<'de>,
    T: serde::Deserialize<'de>,
{
    AtMost::<PhantomData<T>>::items(N).deserialize(deserializer)
}

/// `#[serde(deserialize_with = "option_vec_at_most::<_, _, N>")]`: an
/// optional `Vec<T>` of at most `N` items (`null` or absent is `None`).
pub fn option_vec_at_most<'de, D, T, const N: usize>(
    deserializer: D,
) -> Result<Option<Vec<T>>, D::Error>
where
    D: Deserializer<'de>,
    T: serde::Deserialize<'de>,
{
    struct Maybe<T, const N: usize>(PhantomData<T>);
    impl<'de, T: serde::Deserialize<'de>, const N: usize> Visitor<'de> for Maybe<T, N> {
        type Value = Option<Vec<T>>;
        fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
            write!(f, "null or an array of at most {N} items")
        }
        fn visit_none<E>(self) -> Result<Self::Value, E> {
            Ok(None)
        }
        fn visit_unit<E>(self) -> Result<Self::Value, E> {
            Ok(None)
        }
        fn visit_some<D: Deserializer<'de>>(self, d: D) -> Result<Self::Value, D::Error> {
            vec_at_most::<D, T, N>(d).map(Some)
        }
    }
    deserializer.deserialize_option(Maybe::<T, N>(PhantomData))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Debug, serde::Deserialize)]
    struct Capped {
        #[serde(deserialize_with = "vec_at_most::<_, _, 3>")]
        v: Vec<f64>,
        #[serde(default, deserialize_with = "option_vec_at_most::<_, _, 2>")]
        o: Option<Vec<u8>>,
    }

    #[test]
    fn the_item_past_the_cap_is_refused() {
        let ok: Capped = serde_json::from_str(r#"{"v": [1, 2, 3], "o": [1, 2]}"#).unwrap();
        assert_eq!((ok.v.len(), ok.o.map(|o| o.len())), (3, Some(2)));
        let none: Capped = serde_json::from_str(r#"{"v": [], "o": null}"#).unwrap();
        assert!(none.o.is_none());
        let absent: Capped = serde_json::from_str(r#"{"v": []}"#).unwrap();
        assert!(absent.o.is_none());
        let e = serde_json::from_str::<Capped>(r#"{"v": [1, 2, 3, 4]}"#).unwrap_err();
        assert!(e.to_string().contains("at most 3 items"), "{e}");
        let e = serde_json::from_str::<Capped>(r#"{"v": [], "o": [1, 2, 3]}"#).unwrap_err();
        assert!(e.to_string().contains("at most 2 items"), "{e}");
        let nested = AtMost {
            max: 2,
            item: AtMost::<PhantomData<f64>>::items(1),
        };
        let mut de = serde_json::Deserializer::from_str("[[1], [2]]");
        assert_eq!(
            nested.deserialize(&mut de).unwrap(),
            vec![vec![1.0], vec![2.0]]
        );
        let mut de = serde_json::Deserializer::from_str("[[1, 2]]");
        assert!(nested.deserialize(&mut de).is_err());
    }
}
