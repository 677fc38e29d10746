//! JSON-schema validation of values against `api/openapi.yaml`, through the
//! `jsonschema` crate (draft 2020-12, the dialect OpenAPI 3.1 uses).
//!
//! A sub-schema of the spec (a response's `schema`, a component) is
//! validated inside the whole spec document, so its local `$ref`s
//! (`#/components/schemas/...`) resolve. The spec's own keywords are
//! checked against the 2020-12 vocabulary plus OpenAPI's annotations, so a
//! misspelt keyword (`requried`) fails the contract test instead of being
//! ignored as an unknown annotation.

use serde_json::{json, Value};

/// Every violation of `schema` (a sub-schema of the spec `root`) by
/// `value`, as "instance path: message" lines.
pub fn validate(root: &Value, schema: &Value, value: &Value) -> Vec<String> {
    let mut document = root.clone();
    if let Some(map) = document.as_object_mut() {
        map.insert("allOf".into(), json!([schema]));
    }
    let validator = match jsonschema::options()
        .with_draft(jsonschema::Draft::Draft202012)
        .build(&document)
    {
        Ok(v) => v,
        Err(e) => return vec![format!("the schema does not compile: {e}")],
    };
    validator
        .iter_errors(value)
        .map(|e| format!("${}: {e}", e.instance_path()))
        .collect()
}

/// Keywords whose value is a map from names to schemas.
const SCHEMA_MAPS: [&str; 3] = ["properties", "patternProperties", "$defs"];
/// Keywords whose value is a schema or a list of schemas.
const SUBSCHEMAS: [&str; 11] = [
    "allOf",
    "unevaluatedProperties",
    "anyOf",
    "oneOf",
    "not",
    "if",
    "then",
    "else",
    "items",
    "prefixItems",
    "additionalProperties",
];
/// The other keywords a schema in the spec may use: JSON Schema 2020-12's
/// core, validation and annotation vocabularies, and OpenAPI 3.1's.
const OTHER_KEYWORDS: [&str; 33] = [
    "$ref",
    "$id",
    "$schema",
    "$comment",
    "contains",
    "type",
    "enum",
    "const",
    "multipleOf",
    "maximum",
    "exclusiveMaximum",
    "minimum",
    "exclusiveMinimum",
    "maxLength",
    "minLength",
    "pattern",
    "maxItems",
    "minItems",
    "uniqueItems",
    "maxProperties",
    "minProperties",
    "required",
    "format",
    "title",
    "description",
    "default",
    "deprecated",
    "examples",
    "example",
    "discriminator",
    "contentMediaType",
    "contentEncoding",
    "readOnly",
];

fn is_known(keyword: &str) -> bool {
    [&SCHEMA_MAPS[..], &SUBSCHEMAS[..], &OTHER_KEYWORDS[..]]
        .iter()
        .any(|list| list.contains(&keyword))
}

/// Every keyword of `schema` (and its sub-schemas) outside
/// the known keywords, as "path: keyword" lines.
pub fn unknown_keywords(schema: &Value, path: &str) -> Vec<String> {
    let Some(map) = schema.as_object() else {
        return Vec::new();
    };
    let mut found = Vec::new();
    for (key, sub) in map {
        let here = format!("{path}/{key}");
        if !is_known(key) {
            found.push(format!("{path}: {key}"));
        } else if SCHEMA_MAPS.contains(&key.as_str()) {
            for (name, s) in sub.as_object().into_iter().flatten() {
                found.extend(unknown_keywords(s, &format!("{here}/{name}")));
            }
        } else if SUBSCHEMAS.contains(&key.as_str()) {
            match sub {
                Value::Array(list) => {
                    for (i, s) in list.iter().enumerate() {
                        found.extend(unknown_keywords(s, &format!("{here}/{i}")));
                    }
                }
                s => found.extend(unknown_keywords(s, &here)),
            }
        }
    }
    found
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn validator_accepts_and_rejects() {
        let root = json!({"defs": {"N": {"type": "number", "minimum": 0}}});
        let schema = json!({
            "type": "object", "required": ["a"], "additionalProperties": false,
            "properties": {"a": {"type": "array", "items": {"$ref": "#/defs/N"}, "maxItems": 2},
                           "b": {"oneOf": [{"type": "null"}, {"type": "string"}]}}
        });
        assert!(validate(&root, &schema, &json!({"a": [1, 2], "b": null})).is_empty());
        assert_eq!(validate(&root, &schema, &json!({"a": [1, -2]})).len(), 1);
        assert_eq!(validate(&root, &schema, &json!({"a": [1, 2, 3]})).len(), 1);
        assert_eq!(validate(&root, &schema, &json!({"b": "x"})).len(), 1);
        assert_eq!(validate(&root, &schema, &json!({"a": [], "c": 1})).len(), 1);
        assert_eq!(validate(&root, &schema, &json!({"a": [], "b": 3})).len(), 1);
        // A dangling reference is an error, not a pass.
        assert!(!validate(&root, &json!({"$ref": "#/defs/Missing"}), &json!(1)).is_empty());
    }

    #[test]
    fn misspelt_keywords_are_found_at_any_depth() {
        let schema = json!({
            "type": "object", "requried": ["a"],
            "properties": {"a": {"oneOf": [{"type": "null"}, {"maxitems": 2}]}}
        });
        assert_eq!(
            unknown_keywords(&schema, "#"),
            vec![
                "#/properties/a/oneOf/1: maxitems".to_string(),
                "#: requried".to_string()
            ]
        );
    }
}
