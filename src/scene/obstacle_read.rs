//! Reading an [`Obstacle`] from JSON within what its size allows.
//!
//! The id may come after the geometry, so the members are read first, each
//! into the least it needs: `points` straight into its typed, capped
//! vector, `points_base64` into its string, every other member into a small
//! JSON value of at most [`MAX_MEMBER_VALUES`] values. The shape is then
//! read from them by [`ObstacleShape`]'s derived, tagged reading, so serde's
//! messages (unknown and missing fields per type) are the client's. This
//! works from any deserializer, serde's buffered `Content` included (a
//! dataset record's flattened scene).

use super::obstacle::{Obstacle, ObstacleShape, MAX_CLOUD_POINTS};
use serde::{Deserialize, Deserializer};

impl<'de> Deserialize<'de> for Obstacle {
    /// `id` plus the fields of one [`ObstacleShape`] variant; unknown fields
    /// are rejected and errors mention the id (how: the module docs).
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> std::result::Result<Self, D::Error> {
        use serde::de::Error as _;
        let members = deserializer.deserialize_map(MembersVisitor)?;
        members.into_obstacle().map_err(D::Error::custom)
    }
}

/// A dataset's label on an obstacle placed across the demonstrated path
/// after the demonstrations (`dpmp data generate --intruders`): read and
/// set aside, so that every scene dPMP writes can be posted as it is. The
/// planner treats the obstacle like any other.
pub const INTRUDER_FIELD: &str = "intruder";

/// Most members an obstacle object may have (the berry's six fields, `id`,
/// `type` and the `intruder` label).
const MAX_OBSTACLE_MEMBERS: usize = 9;

/// Most JSON values (numbers, strings, arrays, ... counted through their
/// nesting) one member other than `points` may hold: a quaternion is 5.
pub const MAX_MEMBER_VALUES: usize = 64;

/// Longest string (bytes) a member other than `points_base64` may hold (an
/// id, a type).
pub const MAX_MEMBER_STRING: usize = 256;

/// An obstacle's members as read.
#[derive(Default)]
struct Members {
    small: serde_json::Map<String, serde_json::Value>,
    points: Option<Vec<[f64; 3]>>,
    points_base64: Option<String>,
}

struct MembersVisitor;

impl<'de> serde::de::Visitor<'de> for MembersVisitor {
    type Value = Members;

    fn expecting(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("an obstacle object with `id` and `type`")
    }

    fn visit_map<A: serde::de::MapAccess<'de>>(
        self,
        mut map: A,
    ) -> std::result::Result<Members, A::Error> {
        use serde::de::Error as _;
        let mut members = Members::default();
        let mut count = 0;
        while let Some(key) = map.next_key::<String>()? {
            count += 1;
            if count > MAX_OBSTACLE_MEMBERS {
                return Err(A::Error::custom(format!(
                    "an obstacle has at most {MAX_OBSTACLE_MEMBERS} fields"
                )));
            }
            match key.as_str() {
                "points" => {
                    members.points = Some(map.next_value_seed(crate::strict_json::AtMost::<
                        std::marker::PhantomData<[f64; 3]>,
                    >::items(
                        MAX_CLOUD_POINTS
                    ))?)
                }
                INTRUDER_FIELD => {
                    let _label: bool = map.next_value().map_err(|_| {
                        A::Error::custom(format!("{INTRUDER_FIELD} must be true or false"))
                    })?;
                }
                POINTS_BASE64_FIELD => {
                    members.points_base64 = Some(map.next_value().map_err(|_| {
                        A::Error::custom(format!("{POINTS_BASE64_FIELD} must be a base64 string"))
                    })?)
                }
                _ => {
                    let value = map.next_value_seed(SmallValue {
                        budget: &mut (MAX_MEMBER_VALUES as isize),
                    })?;
                    members.small.insert(key, value);
                }
            }
        }
        Ok(members)
    }
}

impl Members {
    /// The obstacle the members describe, or what is wrong with them.
    fn into_obstacle(mut self) -> std::result::Result<Obstacle, String> {
        let id = match self.small.remove("id") {
            Some(serde_json::Value::String(id)) => id,
            Some(other) => return Err(format!("obstacle id must be a string, got {other}")),
            None => return Err("obstacle without an \"id\"".into()),
        };
        let shape = self
            .shape()
            .map_err(|e| format!("obstacle \"{id}\": {e}"))?;
        Ok(Obstacle { id, shape })
    }

    /// The geometry: the small members read as the tagged [`ObstacleShape`]
    /// (its own messages for unknown and missing fields), the points put in
    /// after.
    fn shape(mut self) -> std::result::Result<ObstacleShape, String> {
        let kind = self
            .small
            .get("type")
            .and_then(|t| t.as_str())
            .unwrap_or("");
        if self.points_base64.is_some() && kind != "points" {
            return Err(format!(
                "{POINTS_BASE64_FIELD} applies only to type \"points\""
            ));
        }
        let points = match (self.points.take(), self.points_base64.take()) {
            (Some(_), Some(_)) => {
                return Err(format!("send points or {POINTS_BASE64_FIELD}, not both"))
            }
            (Some(points), None) => Some(points),
            (None, Some(text)) => Some(decode_compact_points(&text)?),
            (None, None) => None,
        };
        // The shape's own reading sees a placeholder where the points are,
        // so that a misplaced or missing `points` gets serde's message.
        if points.is_some() {
            self.small
                .insert("points".into(), serde_json::Value::Array(Vec::new()));
        }
        let mut shape = ObstacleShape::deserialize(serde_json::Value::Object(self.small))
            .map_err(|e| e.to_string())?;
        if let (
            Some(points),
            ObstacleShape::Convex { points: slot } | ObstacleShape::Points { points: slot, .. },
        ) = (points, &mut shape)
        {
            *slot = points;
        }
        Ok(shape)
    }
}

/// Reads any JSON value of at most `budget` values in all (strings of at
/// most [`MAX_MEMBER_STRING`] bytes), refusing the first beyond.
struct SmallValue<'b> {
    budget: &'b mut isize,
}

impl SmallValue<'_> {
    fn spend<E: serde::de::Error>(&mut self) -> std::result::Result<(), E> {
        *self.budget -= 1;
        if *self.budget < 0 {
            return Err(E::custom(format!(
                "too long: an obstacle field holds at most {MAX_MEMBER_VALUES} values"
            )));
        }
        Ok(())
    }
}

impl<'de> serde::de::DeserializeSeed<'de> for SmallValue<'_> {
    type Value = serde_json::Value;

    fn deserialize<D: Deserializer<'de>>(
        self,
        deserializer: D,
    ) -> std::result::Result<serde_json::Value, D::Error> {
        deserializer.deserialize_any(self)
    }
}

impl<'de> serde::de::Visitor<'de> for SmallValue<'_> {
    type Value = serde_json::Value;

    fn expecting(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("a JSON value")
    }

    fn visit_bool<E: serde::de::Error>(mut self, v: bool) -> std::result::Result<Self::Value, E> {
        self.spend()?;
        Ok(v.into())
    }

    fn visit_i64<E: serde::de::Error>(mut self, v: i64) -> std::result::Result<Self::Value, E> {
        self.spend()?;
        Ok(v.into())
    }

    fn visit_u64<E: serde::de::Error>(mut self, v: u64) -> std::result::Result<Self::Value, E> {
        self.spend()?;
        Ok(v.into())
    }

    fn visit_f64<E: serde::de::Error>(mut self, v: f64) -> std::result::Result<Self::Value, E> {
        self.spend()?;
        Ok(serde_json::Number::from_f64(v).map_or(serde_json::Value::Null, Into::into))
    }

    fn visit_str<E: serde::de::Error>(mut self, v: &str) -> std::result::Result<Self::Value, E> {
        self.spend()?;
        if v.len() > MAX_MEMBER_STRING {
            return Err(E::custom(format!(
                "too long: a string of {} bytes where at most {MAX_MEMBER_STRING} are accepted",
                v.len()
            )));
        }
        Ok(v.into())
    }

    fn visit_unit<E: serde::de::Error>(mut self) -> std::result::Result<Self::Value, E> {
        self.spend()?;
        Ok(serde_json::Value::Null)
    }

    fn visit_none<E: serde::de::Error>(self) -> std::result::Result<Self::Value, E> {
        self.visit_unit()
    }

    fn visit_some<D: Deserializer<'de>>(
        self,
        deserializer: D,
    ) -> std::result::Result<Self::Value, D::Error> {
        deserializer.deserialize_any(self)
    }

    fn visit_seq<A: serde::de::SeqAccess<'de>>(
        mut self,
        mut seq: A,
    ) -> std::result::Result<Self::Value, A::Error> {
        self.spend()?;
        let mut items = Vec::new();
        while let Some(item) = seq.next_element_seed(SmallValue {
            budget: &mut *self.budget,
        })? {
            items.push(item);
        }
        Ok(serde_json::Value::Array(items))
    }

    fn visit_map<A: serde::de::MapAccess<'de>>(
        mut self,
        mut map: A,
    ) -> std::result::Result<Self::Value, A::Error> {
        self.spend()?;
        let mut object = serde_json::Map::new();
        while let Some(key) = map.next_key::<String>()? {
            self.spend()?;
            let value = map.next_value_seed(SmallValue {
                budget: &mut *self.budget,
            })?;
            object.insert(key, value);
        }
        Ok(serde_json::Value::Object(object))
    }
}

/// The compact form of a `points` obstacle's cloud: `points_base64`, the
/// points as little-endian `f32` x, y, z triples (12 bytes a point) in
/// standard base64, instead of `points`.
pub const POINTS_BASE64_FIELD: &str = "points_base64";

/// The points a `points_base64` member encodes (exact: every `f32` is an
/// `f64`); an error says what is wrong with it.
fn decode_compact_points(text: &str) -> std::result::Result<Vec<[f64; 3]>, String> {
    use base64::Engine as _;
    let bytes = base64::engine::general_purpose::STANDARD
        .decode(text.trim())
        .map_err(|e| format!("{POINTS_BASE64_FIELD} is not base64: {e}"))?;
    if bytes.len() % 12 != 0 {
        return Err(format!(
            "{POINTS_BASE64_FIELD} holds {} bytes, not a whole number of 12-byte points (x, y, z as little-endian f32)",
            bytes.len()
        ));
    }
    if bytes.len() / 12 > MAX_CLOUD_POINTS {
        return Err(format!(
            "{POINTS_BASE64_FIELD} holds {} points, more than the {MAX_CLOUD_POINTS} allowed",
            bytes.len() / 12
        ));
    }
    let coordinate = |c: &[u8]| f64::from(f32::from_le_bytes([c[0], c[1], c[2], c[3]]));
    let mut points = Vec::with_capacity(bytes.len() / 12);
    for (i, p) in bytes.chunks_exact(12).enumerate() {
        let xyz = [
            coordinate(&p[0..4]),
            coordinate(&p[4..8]),
            coordinate(&p[8..12]),
        ];
        if xyz.iter().any(|c| !c.is_finite()) {
            return Err(format!(
                "{POINTS_BASE64_FIELD}: point {i} has a non-finite coordinate {xyz:?}"
            ));
        }
        points.push(xyz);
    }
    Ok(points)
}
