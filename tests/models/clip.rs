//! CLIP: tokenizer ids against open_clip's, preprocessing against open_clip's pixel values, and
//! the stand-in encoders (colour embeddings) end to end through masked crops.

use crate::models_support;

use models_support::{clip_fixtures_dir, discs_image, tiny_models_dir};
use segsplat_vision::models::clip::{
    ClipImageEncoder, ClipTextEncoder, ClipTokenizer, clip_pixel_values, masked_square_crop,
};
use segsplat_vision::models::manifest::{Manifest, Preprocess, Role};

#[derive(serde::Deserialize)]
struct TokenizerCase {
    text: String,
    ids: Vec<i64>,
}

fn tokenizer() -> ClipTokenizer {
    ClipTokenizer::from_file(&tiny_models_dir().join("tokenizer.json"), 77, 49406, 49407).unwrap()
}

fn cases(file: &str) -> Vec<TokenizerCase> {
    let text = std::fs::read_to_string(clip_fixtures_dir().join(file)).unwrap();
    serde_json::from_str(&text).unwrap()
}

fn mismatches(tokenizer: &ClipTokenizer, cases: &[TokenizerCase]) -> Vec<String> {
    cases
        .iter()
        .filter_map(|case| {
            let ids = tokenizer.encode(&case.text).unwrap();
            (ids != case.ids).then(|| format!("{:?}: {:?} != {:?}", case.text, ids, case.ids))
        })
        .collect()
}

#[test]
fn tokenizer_matches_open_clip_on_every_case() {
    let tokenizer = tokenizer();
    let cases = cases("tokenizer_cases.json");
    assert!(cases.len() >= 20);
    let mismatches = mismatches(&tokenizer, &cases);
    println!(
        "tokenizer: {}/{} cases match open_clip",
        cases.len() - mismatches.len(),
        cases.len()
    );
    assert!(mismatches.is_empty(), "{}", mismatches.join("\n"));
}

#[test]
fn texts_open_clip_cleans_first_match_open_clip() {
    // ftfy, HTML entities, full width, ligatures, C1 and terminal escapes, case and whitespace:
    // scripts/make_tokenizer_table.py, plus the first cleaning cases recorded.
    let tokenizer = tokenizer();
    let table = cases("tokenizer_open_clip_table.json");
    assert!(table.len() >= 30);
    let all: Vec<TokenizerCase> = table
        .into_iter()
        .chain(cases("tokenizer_cleaning_cases.json"))
        .collect();
    let mismatches = mismatches(&tokenizer, &all);
    println!(
        "tokenizer clean-up: {}/{} cases match open_clip",
        all.len() - mismatches.len(),
        all.len()
    );
    assert!(mismatches.is_empty(), "{}", mismatches.join("\n"));
}

#[test]
fn long_texts_keep_end_of_text_at_the_last_position() {
    let ids = tokenizer().encode(&"word ".repeat(200)).unwrap();
    assert_eq!(ids.len(), 77);
    assert_eq!(ids[76], 49407);
    assert!(ids[1..76].iter().all(|id| *id != 0 && *id != 49407));
}

fn read_npy_f32(path: &std::path::Path) -> (Vec<u64>, Vec<f32>) {
    let bytes = std::fs::read(path).unwrap();
    let npy = npyz::NpyFile::new(&bytes[..]).unwrap();
    let shape = npy.shape().to_vec();
    (shape, npy.into_vec::<f32>().unwrap())
}

#[test]
fn preprocessing_matches_open_clip_pixel_values() {
    let manifest = Manifest::load(&tiny_models_dir()).unwrap();
    let Preprocess::ClipImage(preprocess) = &manifest.model(Role::ClipImage).unwrap().preprocess
    else {
        panic!("clip_image preprocess");
    };
    for (image_file, values_file) in [
        ("preprocess_97x61.png", "preprocess_97x61_pixel_values.npy"),
        (
            "preprocess_300x200.png",
            "preprocess_300x200_pixel_values.npy",
        ),
    ] {
        let image = image::open(clip_fixtures_dir().join(image_file))
            .unwrap()
            .to_rgb8();
        let (shape, expected) = read_npy_f32(&clip_fixtures_dir().join(values_file));
        assert_eq!(shape, vec![1, 3, 224, 224]);
        let actual = clip_pixel_values(&image, preprocess);
        assert_eq!(actual.len(), expected.len());
        let errors: Vec<f32> = actual
            .iter()
            .zip(&expected)
            .map(|(a, b)| (a - b).abs())
            .collect();
        let max = errors.iter().copied().fold(0f32, f32::max);
        let mean = errors.iter().sum::<f32>() / errors.len() as f32;
        println!("{image_file}: max abs error {max:.2e}, mean {mean:.2e} (normalised units)");
        // Pillow's resampling is reproduced in fixed point, so only float rounding remains.
        assert!(max < 1e-4, "{image_file}: max abs error {max}");
    }
}

#[test]
fn a_red_crop_is_closest_to_red_among_colour_words() {
    let Some(store) = models_support::tiny_store() else {
        return;
    };
    let text = ClipTextEncoder::new(&store, 64).unwrap();
    let images = ClipImageEncoder::new(&store).unwrap();
    let (image, truths) = discs_image(
        160,
        120,
        &[
            (45.0, 50.0, 25.0, [220, 30, 30]),
            (115.0, 70.0, 30.0, [30, 40, 210]),
        ],
    );
    let crops: Vec<image::RgbImage> = truths
        .iter()
        .map(|mask| masked_square_crop(&image, mask).unwrap().unwrap())
        .collect();
    let crop_embeddings = images.encode(&crops).unwrap();
    let words = [
        "red", "green", "blue", "yellow", "orange", "purple", "pink", "brown", "white", "gray",
        "black",
    ];
    let word_embeddings = text.encode(&words).unwrap();
    let dot = |a: &[f32], b: &[f32]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f32>();
    for (crop, expected) in crop_embeddings.iter().zip(["red", "blue"]) {
        let norm = dot(crop, crop).sqrt();
        assert!((norm - 1.0).abs() < 1e-5);
        let scores: Vec<f32> = word_embeddings.iter().map(|word| dot(crop, word)).collect();
        let best = scores
            .iter()
            .enumerate()
            .max_by(|a, b| a.1.total_cmp(b.1))
            .map(|(index, _)| words[index])
            .unwrap();
        assert_eq!(best, expected, "scores {scores:?}");
        let best_score = scores.iter().copied().fold(f32::MIN, f32::max);
        assert!(best_score > 0.9, "{best_score}");
    }
    // A second call is served from the cache and gives the same vectors.
    let again = text.encode(&["red"]).unwrap();
    assert!(std::sync::Arc::ptr_eq(&again[0], &word_embeddings[0]));
}
