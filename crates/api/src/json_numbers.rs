//! JSON does not tell `3` from `3.0`, and neither does JSON Schema: `3.0` is an `integer` there.
//! serde does (it refuses `3.0` for a `u32`), so request bodies pass through [`whole_numbers`]
//! first: a float with no fractional part becomes the integer it equals, and a client whose JSON
//! library writes every number as a float is not refused for it.

use serde_json::{Number, Value};

/// `value` with every integral float that fits an `i64` or `u64` written as that integer.
pub fn whole_numbers(value: Value) -> Value {
    match value {
        Value::Number(number) => Value::Number(whole_number(number)),
        Value::Array(items) => Value::Array(items.into_iter().map(whole_numbers).collect()),
        Value::Object(fields) => Value::Object(
            fields
                .into_iter()
                .map(|(name, field)| (name, whole_numbers(field)))
                .collect(),
        ),
        other => other,
    }
}

fn whole_number(number: Number) -> Number {
    let Some(float) = number.as_f64().filter(|_| number.is_f64()) else {
        return number;
    };
    if float.fract() != 0.0 {
        return number;
    }
    // Exact bounds: 2^63 and 2^64 are the first floats past each range.
    if (-9.223_372_036_854_776e18..9.223_372_036_854_776e18).contains(&float) {
        Number::from(float as i64)
    } else if (0.0..1.844_674_407_370_955_2e19).contains(&float) {
        Number::from(float as u64)
    } else {
        number
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    #[test]
    fn integral_floats_become_integers() {
        let sent = json!({"a": 3.0, "b": [1.5, -2.0, 1e300], "c": {"d": 7, "e": "8.0"}});
        let read = whole_numbers(sent);
        assert_eq!(
            read,
            json!({"a": 3, "b": [1.5, -2, 1e300], "c": {"d": 7, "e": "8.0"}})
        );
        assert!(read["a"].is_u64() || read["a"].is_i64());
        assert_eq!(
            whole_numbers(json!(1.8e19)),
            json!(18_000_000_000_000_000_000_u64)
        );
    }
}
