//! A plain-text rendering of a [`SegmentationReport`] for logs and the CLI. IoUs are shown in
//! percent, as the papers print them.

use std::collections::BTreeMap;
use std::fmt::Write;

use super::segmentation_metrics::SegmentationReport;

/// One row per query text (mean IoU and the frames it was scored in), one row per frame, then
/// the overall mIoU.
pub fn report_table(report: &SegmentationReport) -> String {
    let mut counts: BTreeMap<&str, usize> = BTreeMap::new();
    for query in report.frames.iter().flat_map(|frame| &frame.queries) {
        *counts.entry(query.text.as_str()).or_default() += 1;
    }
    let query_width = column_width("query", report.per_query.keys().map(String::as_str));
    let frame_width = column_width(
        "frame",
        report.frames.iter().map(|frame| frame.frame_name.as_str()),
    );

    // Writing into a String cannot fail, so the results are ignored.
    let mut table = String::new();
    let _ = writeln!(
        table,
        "{:<query_width$}  {:>7}  {:>6}",
        "query", "IoU %", "frames"
    );
    for (text, iou) in &report.per_query {
        let count = counts.get(text.as_str()).copied().unwrap_or(0);
        let _ = writeln!(
            table,
            "{text:<query_width$}  {:>7.2}  {count:>6}",
            iou * 100.0
        );
    }
    let _ = writeln!(table);
    let _ = writeln!(
        table,
        "{:<frame_width$}  {:>6}  {:>7}  {:>7}",
        "frame", "index", "queries", "IoU %"
    );
    for frame in &report.frames {
        let _ = writeln!(
            table,
            "{:<frame_width$}  {:>6}  {:>7}  {:>7.2}",
            frame.frame_name,
            frame.frame_index,
            frame.queries.len(),
            frame.mean_iou * 100.0
        );
    }
    let _ = writeln!(table);
    let _ = writeln!(
        table,
        "mIoU {:.2}% over {} frames ({} queries)",
        report.miou * 100.0,
        report.frame_count,
        report.query_count
    );
    table
}

fn column_width<'a>(header: &str, cells: impl Iterator<Item = &'a str>) -> usize {
    cells
        .map(|cell| cell.chars().count())
        .fold(header.len(), usize::max)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::segmentation_metrics::{FrameQueryScore, FrameScore, summarize};

    #[test]
    fn table_lists_queries_frames_and_the_overall_miou() {
        let score = |text: &str, iou| FrameQueryScore {
            text: text.to_owned(),
            iou,
        };
        let report = summarize(vec![
            FrameScore {
                frame_name: "frame_00041.jpg".to_owned(),
                frame_index: 40,
                queries: vec![score("old camera", 0.8), score("mug", 0.4)],
                mean_iou: 0.6,
            },
            FrameScore {
                frame_name: "frame_00105.jpg".to_owned(),
                frame_index: 104,
                queries: vec![score("old camera", 0.6)],
                mean_iou: 0.6,
            },
        ]);
        let table = report_table(&report);
        let lines: Vec<&str> = table.lines().collect();
        assert_eq!(lines[0], "query         IoU %  frames");
        assert_eq!(lines[1], "mug           40.00       1");
        assert_eq!(lines[2], "old camera    70.00       2");
        assert_eq!(lines[4], "frame             index  queries    IoU %");
        assert_eq!(lines[5], "frame_00041.jpg      40        2    60.00");
        assert_eq!(lines.last(), Some(&"mIoU 60.00% over 2 frames (3 queries)"));
    }
}
