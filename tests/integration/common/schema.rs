//! A small JSON-schema validator for the subset `api/openapi.yaml` uses:
//! `$ref` (local), `type` (string or list), `properties`, `required`,
//! `additionalProperties`, `items`, `minItems`, `maxItems`, `enum`,
//! `const`, `minimum`, `maximum`, `exclusiveMinimum`, `oneOf`, `anyOf`,
//! `allOf`. Annotations (`description`, `default`, `example`, ...) are
//! ignored. An unknown keyword makes validation fail so the validator
//! cannot silently accept what it does not understand.

use serde_json::Value;

const ANNOTATIONS: [&str; 11] = [
    "description",
    "discriminator",
    "title",
    "default",
    "example",
    "examples",
    "format",
    "contentEncoding",
    "contentMediaType",
    "summary",
    "deprecated",
];

/// Every violation of `schema` by `value`, as "path: message" lines.
pub fn validate(root: &Value, schema: &Value, value: &Value) -> Vec<String> {
    let mut errors = Vec::new();
    check(root, schema, value, "$", &mut errors);
    errors
}

fn check(root: &Value, schema: &Value, value: &Value, path: &str, errors: &mut Vec<String>) {
    let Some(map) = schema.as_object() else {
        errors.push(format!("{path}: schema is not an object: {schema}"));
        return;
    };
    for (key, sub) in map {
        match key.as_str() {
            "$ref" => match resolve(root, sub) {
                Some(target) => check(root, target, value, path, errors),
                None => errors.push(format!("{path}: unresolved $ref {sub}")),
            },
            "type" => check_type(sub, value, path, errors),
            "properties" => {
                if let (Some(props), Some(obj)) = (sub.as_object(), value.as_object()) {
                    for (name, prop_schema) in props {
                        if let Some(v) = obj.get(name) {
                            check(root, prop_schema, v, &format!("{path}.{name}"), errors);
                        }
                    }
                }
            }
            "required" => {
                if let Some(obj) = value.as_object() {
                    for name in sub.as_array().into_iter().flatten() {
                        let name = name.as_str().unwrap_or_default();
                        if !obj.contains_key(name) {
                            errors.push(format!("{path}: missing required property {name}"));
                        }
                    }
                }
            }
            "additionalProperties" => {
                if let Some(obj) = value.as_object() {
                    let known = map.get("properties").and_then(Value::as_object);
                    for (name, v) in obj {
                        if known.is_some_and(|k| k.contains_key(name)) {
                            continue;
                        }
                        match sub {
                            Value::Bool(false) => {
                                errors.push(format!("{path}: unexpected property {name}"))
                            }
                            Value::Bool(true) => {}
                            s => check(root, s, v, &format!("{path}.{name}"), errors),
                        }
                    }
                }
            }
            "items" => {
                if let Some(items) = value.as_array() {
                    for (i, v) in items.iter().enumerate() {
                        check(root, sub, v, &format!("{path}[{i}]"), errors);
                    }
                }
            }
            "minItems" | "maxItems" => {
                if let (Some(items), Some(n)) = (value.as_array(), sub.as_u64()) {
                    let len = items.len() as u64;
                    if (key == "minItems" && len < n) || (key == "maxItems" && len > n) {
                        errors.push(format!("{path}: {len} items violates {key} {n}"));
                    }
                }
            }
            "enum" => {
                if !sub.as_array().is_some_and(|a| a.contains(value)) {
                    errors.push(format!("{path}: {value} not in enum {sub}"));
                }
            }
            "const" => {
                if sub != value {
                    errors.push(format!("{path}: {value} is not the constant {sub}"));
                }
            }
            "minimum" | "maximum" | "exclusiveMinimum" => {
                if let (Some(x), Some(bound)) = (value.as_f64(), sub.as_f64()) {
                    let ok = match key.as_str() {
                        "minimum" => x >= bound,
                        "maximum" => x <= bound,
                        _ => x > bound,
                    };
                    if !ok {
                        errors.push(format!("{path}: {x} violates {key} {bound}"));
                    }
                }
            }
            "allOf" => {
                for s in sub.as_array().into_iter().flatten() {
                    check(root, s, value, path, errors);
                }
            }
            "anyOf" | "oneOf" => {
                let matching = sub
                    .as_array()
                    .into_iter()
                    .flatten()
                    .filter(|s| validate_at(root, s, value, path).is_empty())
                    .count();
                let ok = if key == "oneOf" {
                    matching == 1
                } else {
                    matching >= 1
                };
                if !ok {
                    errors.push(format!("{path}: {matching} alternatives of {key} match"));
                }
            }
            k if ANNOTATIONS.contains(&k) => {}
            other => errors.push(format!("{path}: unsupported schema keyword {other}")),
        }
    }
}

fn validate_at(root: &Value, schema: &Value, value: &Value, path: &str) -> Vec<String> {
    let mut errors = Vec::new();
    check(root, schema, value, path, &mut errors);
    errors
}

fn resolve<'a>(root: &'a Value, reference: &Value) -> Option<&'a Value> {
    let pointer = reference.as_str()?.strip_prefix('#')?;
    root.pointer(pointer)
}

fn check_type(types: &Value, value: &Value, path: &str, errors: &mut Vec<String>) {
    let names: Vec<&str> = match types {
        Value::String(s) => vec![s.as_str()],
        Value::Array(a) => a.iter().filter_map(Value::as_str).collect(),
        _ => vec![],
    };
    let ok = names.iter().any(|t| match *t {
        "object" => value.is_object(),
        "array" => value.is_array(),
        "string" => value.is_string(),
        "boolean" => value.is_boolean(),
        "null" => value.is_null(),
        "number" => value.is_number(),
        "integer" => value.is_u64() || value.is_i64(),
        _ => false,
    });
    if !ok {
        errors.push(format!("{path}: {value} is not of type {types}"));
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

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
        assert_eq!(validate(&root, &json!({"typo": 1}), &json!(1)).len(), 1);
    }
}
