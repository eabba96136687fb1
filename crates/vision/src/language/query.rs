//! Query scoring (docs/method.md stage 4): cosine of the text embedding with every object embedding,
//! a granularity policy, top-k, and a calibrated "no match" so a caller can hear that nothing in
//! the scene fits the text.
//!
//! ## Relevancy
//! Following LERF, an object's relevancy to query `q` is measured against canonical phrases
//! `c_1..c_n` ([`CANONICAL_PHRASES`]) that describe "any object":
//!
//! ```text
//! relevancy(o) = min_i  exp(T cos(q, o)) / (exp(T cos(q, o)) + exp(T cos(c_i, o)))
//!              = sigmoid(T * (cos(q, o) - max_i cos(c_i, o)))          with T = 10
//! ```
//!
//! i.e. the pairwise softmax of the query against the canonical phrase the object is closest to.
//! 0.5 means "the text fits this object exactly as well as 'object' does": it names nothing the
//! canonical phrases do not. An object matches when its relevancy is at least the threshold.
//!
//! ## Calibration of the default threshold
//! The default is [`DEFAULT_RELEVANCY_THRESHOLD`] = 0.55, not 0.5: a text the encoder cannot tell
//! from a canonical phrase sits at 0.5 up to rounding (with the stand-in test CLIP every text
//! without a colour word embeds exactly like "object"; with real CLIP vague texts come close), so
//! 0.5 would accept it or not by the last bit. 0.55 asks for a cosine margin of
//! `ln(0.55 / 0.45) / 10 = 0.020` over the best canonical phrase, which is small next to the
//! margins a fitting text has (0.05 to 0.1 for real CLIP in LERF's plots, ~0.9 for the stand-in).

use std::str::FromStr;

use serde::{Deserialize, Serialize};

use segsplat_scene::Level;

/// The phrases LERF compares every query against.
pub const CANONICAL_PHRASES: [&str; 4] = ["object", "things", "stuff", "texture"];
/// Softmax temperature of the relevancy (LERF's).
pub const RELEVANCY_TEMPERATURE: f32 = 10.0;
/// See the module documentation for why it is above 0.5.
pub const DEFAULT_RELEVANCY_THRESHOLD: f32 = 0.55;
/// The most objects one query may ask for.
pub const MAX_TOP_K: usize = 100;

/// Which level(s) a query picks from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Granularity {
    /// Middle and large objects ranked together: the top answer is the better of the best
    /// middle and the best large object, as the paper's evaluation picks.
    #[default]
    Auto,
    Small,
    Middle,
    Large,
}

#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum QueryOptionsError {
    #[error("granularity: unknown value {0:?}; expected auto, small, middle or large")]
    Granularity(String),
    #[error("top_k: {0} is outside 1..={MAX_TOP_K}")]
    TopK(usize),
    #[error("threshold: {0} is outside 0..=1")]
    Threshold(f32),
}

impl FromStr for Granularity {
    type Err = QueryOptionsError;

    fn from_str(text: &str) -> Result<Self, Self::Err> {
        match text {
            "auto" => Ok(Granularity::Auto),
            "small" => Ok(Granularity::Small),
            "middle" => Ok(Granularity::Middle),
            "large" => Ok(Granularity::Large),
            other => Err(QueryOptionsError::Granularity(other.to_string())),
        }
    }
}

impl Granularity {
    /// Whether objects of `level` compete under this policy.
    pub fn admits(self, level: Level) -> bool {
        match self {
            Granularity::Auto => matches!(level, Level::Middle | Level::Large),
            Granularity::Small => level == Level::Small,
            Granularity::Middle => level == Level::Middle,
            Granularity::Large => level == Level::Large,
        }
    }
}

/// How to pick the answer.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct QueryOptions {
    pub granularity: Granularity,
    pub top_k: usize,
    /// Minimum relevancy for a match.
    pub threshold: f32,
}

impl Default for QueryOptions {
    fn default() -> Self {
        Self {
            granularity: Granularity::Auto,
            top_k: 1,
            threshold: DEFAULT_RELEVANCY_THRESHOLD,
        }
    }
}

impl QueryOptions {
    pub fn validate(&self) -> Result<(), QueryOptionsError> {
        if !(1..=MAX_TOP_K).contains(&self.top_k) {
            return Err(QueryOptionsError::TopK(self.top_k));
        }
        if !(0.0..=1.0).contains(&self.threshold) {
            return Err(QueryOptionsError::Threshold(self.threshold));
        }
        Ok(())
    }
}

/// An object's embedding, as scoring sees it.
#[derive(Debug, Clone, Copy)]
pub struct CandidateObject<'a> {
    pub level: Level,
    pub object_id: u32,
    pub vector: &'a [f32],
}

/// One scored object.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ScoredObject {
    pub level: Level,
    pub object_id: u32,
    /// Cosine similarity of text and object embeddings.
    pub score: f32,
    /// See the module documentation; in 0..1.
    pub relevancy: f32,
}

/// The answer: the best `top_k` matching objects, best first; `matched` is false (and `objects`
/// empty) when no admitted object reaches the threshold.
#[derive(Debug, Clone, PartialEq)]
pub struct QueryAnswer {
    pub matched: bool,
    pub objects: Vec<ScoredObject>,
}

/// Text and object embeddings of different widths: the CLIP text and image models do not belong
/// together, and no score between them means anything.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error(
    "the text embedding has {text} values but object ({level_name}, {object_id}) has {object}: the CLIP \
     text model and the image model that embedded the objects are not a pair",
    level_name = level.name()
)]
pub struct EmbeddingWidthMismatch {
    pub text: usize,
    pub object: usize,
    pub level: Level,
    pub object_id: u32,
}

/// Cosine similarity; 0 when either vector is zero or their lengths differ (callers that score
/// check widths first: [`answer_query`] refuses a mismatch rather than score it 0).
pub fn cosine(a: &[f32], b: &[f32]) -> f32 {
    if a.len() != b.len() {
        return 0.0;
    }
    let dot: f32 = a.iter().zip(b).map(|(x, y)| x * y).sum();
    let norms =
        a.iter().map(|x| x * x).sum::<f32>().sqrt() * b.iter().map(|y| y * y).sum::<f32>().sqrt();
    if norms > 0.0 { dot / norms } else { 0.0 }
}

/// LERF relevancy of an object to the query (module documentation); 1 without canonical
/// phrases (nothing to compare against).
pub fn relevancy(query: &[f32], canonical: &[&[f32]], object: &[f32]) -> f32 {
    let query_score = cosine(query, object);
    canonical
        .iter()
        .map(|phrase| {
            let margin = query_score - cosine(phrase, object);
            1.0 / (1.0 + (-RELEVANCY_TEMPERATURE * margin).exp())
        })
        .fold(1.0, f32::min)
}

/// Scores every admitted object and keeps the best `top_k` that reach the threshold. Ties in
/// score are broken by (level, id) so answers are stable. An object or canonical phrase whose
/// embedding width differs from the query's is an error, never a silent score of 0.
pub fn answer_query(
    query: &[f32],
    canonical: &[&[f32]],
    objects: &[CandidateObject<'_>],
    options: &QueryOptions,
) -> Result<QueryAnswer, EmbeddingWidthMismatch> {
    if let Some(object) = objects
        .iter()
        .find(|object| object.vector.len() != query.len())
    {
        return Err(EmbeddingWidthMismatch {
            text: query.len(),
            object: object.vector.len(),
            level: object.level,
            object_id: object.object_id,
        });
    }
    let mut scored: Vec<ScoredObject> = objects
        .iter()
        .filter(|object| options.granularity.admits(object.level))
        .map(|object| ScoredObject {
            level: object.level,
            object_id: object.object_id,
            score: cosine(query, object.vector),
            relevancy: relevancy(query, canonical, object.vector),
        })
        .collect();
    scored.sort_by(|a, b| {
        b.score
            .total_cmp(&a.score)
            .then_with(|| (a.level, a.object_id).cmp(&(b.level, b.object_id)))
    });
    let objects: Vec<ScoredObject> = scored
        .into_iter()
        .filter(|object| object.relevancy >= options.threshold)
        .take(options.top_k)
        .collect();
    Ok(QueryAnswer {
        matched: !objects.is_empty(),
        objects,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn unit(values: &[f32]) -> Vec<f32> {
        let norm = values.iter().map(|v| v * v).sum::<f32>().sqrt();
        values.iter().map(|v| v / norm).collect()
    }

    /// Axes: 0 red, 1 green, 2 blue, 3 "generic" (what canonical phrases point at).
    struct Fixture {
        canonical: Vec<f32>,
        objects: Vec<(Level, u32, Vec<f32>)>,
    }

    fn fixture() -> Fixture {
        Fixture {
            canonical: unit(&[0.0, 0.0, 0.0, 1.0]),
            objects: vec![
                (Level::Small, 1, unit(&[1.0, 0.0, 0.0, 0.1])),
                (Level::Small, 2, unit(&[0.0, 1.0, 0.0, 0.1])),
                (Level::Small, 3, unit(&[0.0, 0.0, 1.0, 0.1])),
                (Level::Middle, 1, unit(&[0.7, 0.7, 0.0, 0.1])),
                (Level::Large, 1, unit(&[0.6, 0.6, 0.6, 0.1])),
            ],
        }
    }

    fn ask(fixture: &Fixture, query: &[f32], options: QueryOptions) -> QueryAnswer {
        let candidates: Vec<CandidateObject> = fixture
            .objects
            .iter()
            .map(|(level, object_id, vector)| CandidateObject {
                level: *level,
                object_id: *object_id,
                vector,
            })
            .collect();
        answer_query(query, &[&fixture.canonical], &candidates, &options)
            .expect("the fixture's embeddings share one width")
    }

    fn ids(answer: &QueryAnswer) -> Vec<(Level, u32)> {
        answer
            .objects
            .iter()
            .map(|o| (o.level, o.object_id))
            .collect()
    }

    #[test]
    fn relevancy_is_the_pairwise_softmax_against_the_closest_canonical_phrase() {
        let object = unit(&[1.0, 0.0, 0.0, 1.0]);
        let query = unit(&[1.0, 0.0, 0.0, 0.0]);
        let far = unit(&[0.0, 1.0, 0.0, 0.0]);
        let near = unit(&[0.0, 0.0, 0.0, 1.0]);
        let (q, n) = (cosine(&query, &object), cosine(&near, &object));
        let softmax = (10.0 * q).exp() / ((10.0 * q).exp() + (10.0 * n).exp());
        let value = relevancy(&query, &[&far, &near], &object);
        assert!((value - softmax).abs() < 1e-6, "{value} vs {softmax}");
        assert!((value - 0.5).abs() < 1e-6, "equal cosines give 0.5");
        assert!(relevancy(&query, &[&far], &object) > 0.99);
        assert_eq!(relevancy(&query, &[], &object), 1.0);
    }

    #[test]
    fn small_granularity_picks_the_closest_small_object() {
        let fixture = fixture();
        let options = QueryOptions {
            granularity: Granularity::Small,
            top_k: 3,
            ..QueryOptions::default()
        };
        let red = ask(&fixture, &unit(&[1.0, 0.0, 0.0, 0.1]), options);
        assert!(red.matched);
        assert_eq!(
            ids(&red),
            vec![(Level::Small, 1)],
            "green and blue do not pass"
        );
        assert!(red.objects[0].score > 0.99 && red.objects[0].relevancy > 0.99);
        let blue = ask(&fixture, &unit(&[0.0, 0.0, 1.0, 0.3]), options);
        assert_eq!(ids(&blue)[0], (Level::Small, 3));
    }

    #[test]
    fn auto_keeps_the_better_of_the_middle_and_large_winners() {
        let fixture = fixture();
        let options = QueryOptions {
            top_k: 5,
            threshold: 0.0,
            ..QueryOptions::default()
        };
        let yellowish = ask(&fixture, &unit(&[1.0, 1.0, 0.0, 0.1]), options);
        assert_eq!(
            ids(&yellowish),
            vec![(Level::Middle, 1), (Level::Large, 1)],
            "small objects never compete under auto"
        );
        let grey = ask(&fixture, &unit(&[1.0, 1.0, 1.0, 0.1]), options);
        assert_eq!(ids(&grey)[0], (Level::Large, 1));
        let large_only = QueryOptions {
            granularity: Granularity::Large,
            ..options
        };
        assert_eq!(
            ids(&ask(&fixture, &unit(&[1.0, 1.0, 0.0, 0.1]), large_only)),
            vec![(Level::Large, 1)]
        );
    }

    #[test]
    fn a_text_no_better_than_the_canonical_phrases_is_no_match() {
        let fixture = fixture();
        let options = QueryOptions {
            granularity: Granularity::Small,
            top_k: 3,
            ..QueryOptions::default()
        };
        // Exactly the canonical direction: relevancy 0.5 for every object.
        let vague = ask(&fixture, &fixture.canonical, options);
        assert!(!vague.matched);
        assert!(vague.objects.is_empty());
        // A lower threshold lets the tie through: the threshold is the caller's to set.
        let lenient = QueryOptions {
            threshold: 0.5,
            ..options
        };
        let tied = ask(&fixture, &unit(&[0.0, 0.0, 0.0, 1.0]), lenient);
        assert!(
            tied.objects
                .iter()
                .all(|o| (o.relevancy - 0.5).abs() < 1e-5)
        );
    }

    #[test]
    fn top_k_limits_and_ties_are_ordered_by_level_then_id() {
        let mut fixture = fixture();
        fixture
            .objects
            .push((Level::Small, 0, unit(&[1.0, 0.0, 0.0, 0.1])));
        let options = QueryOptions {
            granularity: Granularity::Small,
            top_k: 1,
            threshold: 0.0,
        };
        let answer = ask(&fixture, &unit(&[1.0, 0.0, 0.0, 0.1]), options);
        assert_eq!(ids(&answer), vec![(Level::Small, 0)]);
    }

    #[test]
    fn options_are_validated_and_granularity_parsed() {
        assert_eq!("middle".parse::<Granularity>(), Ok(Granularity::Middle));
        assert!(matches!(
            "huge".parse::<Granularity>(),
            Err(QueryOptionsError::Granularity(_))
        ));
        let zero = QueryOptions {
            top_k: 0,
            ..QueryOptions::default()
        };
        assert_eq!(zero.validate(), Err(QueryOptionsError::TopK(0)));
        let high = QueryOptions {
            threshold: 1.5,
            ..QueryOptions::default()
        };
        assert_eq!(high.validate(), Err(QueryOptionsError::Threshold(1.5)));
        assert_eq!(QueryOptions::default().validate(), Ok(()));
        assert_eq!(cosine(&[1.0, 0.0], &[1.0]), 0.0);
        assert_eq!(cosine(&[0.0, 0.0], &[1.0, 0.0]), 0.0);
    }

    #[test]
    fn embeddings_of_another_width_are_an_error_not_a_zero_score() {
        let fixture = fixture();
        let wide = unit(&[1.0, 0.0, 0.0, 0.1, 0.0, 0.0]);
        let candidates = [
            CandidateObject {
                level: Level::Small,
                object_id: 1,
                vector: &fixture.objects[0].2,
            },
            CandidateObject {
                level: Level::Small,
                object_id: 7,
                vector: &wide,
            },
        ];
        let query = unit(&[1.0, 0.0, 0.0, 0.0]);
        let error = answer_query(
            &query,
            &[&fixture.canonical],
            &candidates,
            &QueryOptions::default(),
        )
        .expect_err("a 6-wide object against a 4-wide text");
        assert_eq!((error.text, error.object, error.object_id), (4, 6, 7));
        assert!(error.to_string().contains("not a pair"), "{error}");
    }
}
