//! Stage 1 for posed static views, the linking step: the local masks of one level (each view's
//! generator output, ids meaningful only in that view) are tied together by the sparse points
//! that fall in them. A point observed in several views links every pair of masks it falls in
//! there; two masks become one object when their link count is strong relative to the points
//! either holds, and union-find carries that through chains (a-b and b-c make one object even
//! when a and c never share a point).

use std::collections::HashMap;
use std::ops::Range;

use segsplat_vision::segment::{BitMask, BoundingBox};

/// One generator mask of one view, at the training resolution.
#[derive(Debug, Clone)]
pub(super) struct LocalMask {
    /// Index into the views being associated.
    pub view: usize,
    pub mask: BitMask,
    pub bbox: BoundingBox,
    pub area: u64,
}

/// When the points two masks share make them one object.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct LinkRule {
    pub min_links: u32,
    pub min_share: f32,
}

impl LinkRule {
    /// `links` shared points are strong for masks holding `points_a` and `points_b` points when
    /// they are at least `min_links` and at least `min_share` of the smaller holder's points:
    /// relative to the smaller mask, so a small part seen inside a large mask in another view
    /// is not tied to it by the few points they happen to share, while two views of one object
    /// (which share most of the smaller one's visible points) always are.
    fn is_strong(&self, links: u32, points_a: u32, points_b: u32) -> bool {
        let share_needed = (self.min_share * points_a.min(points_b) as f32).ceil() as u32;
        links >= self.min_links.max(share_needed)
    }
}

/// The local masks that share points, grouped.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct Grouping {
    /// Per group, its masks (indices into the local masks), in increasing order; groups in
    /// order of their first mask.
    pub groups: Vec<Vec<usize>>,
    /// Per local mask, whether it has a strong link to any other.
    pub linked: Vec<bool>,
    /// Unions that joined two groups.
    pub merges: usize,
    /// Strong links left out because their groups both hold a mask of one view.
    pub refused_merges: usize,
}

/// Per point, the local masks it falls in (sorted, no repeats), from its positions
/// `(view, [u, v])` in mask pixels. `masks_of_view[view]` is the range of `masks` in that view.
pub(super) fn point_hits(
    masks: &[LocalMask],
    masks_of_view: &[Range<usize>],
    positions_of_points: &[Vec<(usize, [f32; 2])>],
) -> Vec<Vec<usize>> {
    positions_of_points
        .iter()
        .map(|positions| {
            let mut hits: Vec<usize> = positions
                .iter()
                .filter_map(|&(view, position)| masks_of_view.get(view).map(|r| (r, position)))
                .flat_map(|(range, position)| masks_at(masks, range.clone(), position))
                .collect();
            hits.sort_unstable();
            hits.dedup();
            hits
        })
        .collect()
}

/// The masks of one view a position falls in, tolerant to silhouette edges like
/// `ViewMasks::id_near`: the masks holding the position's own pixel; when none does, the masks
/// holding the most (at least 2) of the 4 pixels whose centres surround the position, one mask
/// only (a point on an outline then stays with its object, a point a full pixel away from every
/// mask hits none).
fn masks_at(masks: &[LocalMask], range: Range<usize>, [u, v]: [f32; 2]) -> Vec<usize> {
    let (x, y) = (u as u32, v as u32);
    let own: Vec<usize> = range
        .clone()
        .filter(|&index| contains(&masks[index], x as i64, y as i64))
        .collect();
    if !own.is_empty() {
        return own;
    }
    let (left, top) = ((u - 0.5).floor() as i64, (v - 0.5).floor() as i64);
    let covered = |index: usize| {
        [(0, 0), (1, 0), (0, 1), (1, 1)]
            .into_iter()
            .filter(|(dx, dy)| contains(&masks[index], left + dx, top + dy))
            .count()
    };
    // The one mask covering most of them (the first on a tie), at least 2.
    let best = range
        .map(|index| (covered(index), index))
        .filter(|&(count, _)| count >= 2)
        .min_by_key(|&(count, index)| (std::cmp::Reverse(count), index));
    best.map(|(_, index)| index).into_iter().collect()
}

fn contains(local: &LocalMask, x: i64, y: i64) -> bool {
    let bbox = &local.bbox;
    x >= i64::from(bbox.x_min)
        && y >= i64::from(bbox.y_min)
        && x <= i64::from(bbox.x_max)
        && y <= i64::from(bbox.y_max)
        && local.mask.get(x as u32, y as u32)
}

/// Groups local masks (`view_of_mask`: each one's view) by the points they share (`hits`: per
/// point, the masks it falls in). Links between two masks of different views count the points
/// falling in both. Strong links (see [`LinkRule`]) are unioned, strongest first, except where
/// both groups already hold a mask of the same view: a level's masks in one view are different
/// objects, so such a union would make one object of two, and one stray link would chain whole
/// objects together. For the same reason masks of one view are never linked.
pub(super) fn group_by_shared_points(
    view_of_mask: &[usize],
    hits: &[Vec<usize>],
    rule: LinkRule,
) -> Grouping {
    let mask_count = view_of_mask.len();
    let mut points_in_mask = vec![0u32; mask_count];
    let mut links: HashMap<(usize, usize), u32> = HashMap::new();
    for point_hits in hits {
        for (position, &a) in point_hits.iter().enumerate() {
            points_in_mask[a] += 1;
            for &b in &point_hits[position + 1..] {
                if view_of_mask[a] == view_of_mask[b] {
                    continue;
                }
                *links.entry((a, b)).or_default() += 1;
            }
        }
    }
    // Strongest pairs first (then by index), so the result never depends on hash order.
    let mut strong: Vec<((usize, usize), u32)> = links
        .into_iter()
        .filter(|&((a, b), count)| rule.is_strong(count, points_in_mask[a], points_in_mask[b]))
        .collect();
    strong.sort_unstable_by(|(pair_a, count_a), (pair_b, count_b)| {
        count_b.cmp(count_a).then(pair_a.cmp(pair_b))
    });
    let mut sets = UnionFind::new(view_of_mask);
    let mut linked = vec![false; mask_count];
    let (mut merges, mut refused_merges) = (0, 0);
    for ((a, b), _) in strong {
        linked[a] = true;
        linked[b] = true;
        match sets.union(a, b) {
            Union::Joined => merges += 1,
            Union::Refused => refused_merges += 1,
            Union::Already => {}
        }
    }
    let mut group_of_root: HashMap<usize, usize> = HashMap::new();
    let mut groups: Vec<Vec<usize>> = Vec::new();
    for mask in 0..mask_count {
        let root = sets.find(mask);
        let group = *group_of_root.entry(root).or_insert_with(|| {
            groups.push(Vec::new());
            groups.len() - 1
        });
        groups[group].push(mask);
    }
    Grouping {
        groups,
        linked,
        merges,
        refused_merges,
    }
}

/// Disjoint sets with path halving and union by size, each set knowing its views.
struct UnionFind {
    parent: Vec<usize>,
    /// Per root, the views its masks are in (sorted).
    views: Vec<Vec<usize>>,
}

/// What a union did.
enum Union {
    Joined,
    /// The two sets share a view.
    Refused,
    /// One set already.
    Already,
}

impl UnionFind {
    fn new(view_of_mask: &[usize]) -> Self {
        Self {
            parent: (0..view_of_mask.len()).collect(),
            views: view_of_mask.iter().map(|&view| vec![view]).collect(),
        }
    }

    fn find(&mut self, mut element: usize) -> usize {
        while self.parent[element] != element {
            self.parent[element] = self.parent[self.parent[element]];
            element = self.parent[element];
        }
        element
    }

    /// Joins the sets of `a` and `b` unless they are one or share a view.
    fn union(&mut self, a: usize, b: usize) -> Union {
        let (mut a, mut b) = (self.find(a), self.find(b));
        if a == b {
            return Union::Already;
        }
        if self.views[a].len() < self.views[b].len() {
            std::mem::swap(&mut a, &mut b);
        }
        let (views_a, views_b) = (&self.views[a], &self.views[b]);
        if views_b
            .iter()
            .any(|view| views_a.binary_search(view).is_ok())
        {
            return Union::Refused;
        }
        let mut joined = std::mem::take(&mut self.views[a]);
        joined.append(&mut self.views[b]);
        joined.sort_unstable();
        self.views[a] = joined;
        self.parent[b] = a;
        Union::Joined
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const RULE: LinkRule = LinkRule {
        min_links: 3,
        min_share: 0.3,
    };

    #[test]
    fn chains_merge_fully_and_weak_links_do_not() {
        // Masks 0-1 share 4 points, 1-2 share 4, 3 shares 1 point with 2 (weak), 4 nothing.
        // (Each mask in its own view.)
        let mut hits = Vec::new();
        hits.extend(std::iter::repeat_n(vec![0, 1], 4));
        hits.extend(std::iter::repeat_n(vec![1, 2], 4));
        hits.push(vec![2, 3]);
        hits.push(vec![4]);
        let grouping = group_by_shared_points(&[0, 1, 2, 3, 4], &hits, RULE);
        assert_eq!(grouping.groups, vec![vec![0, 1, 2], vec![3], vec![4]]);
        assert_eq!(grouping.merges, 2);
        assert_eq!(grouping.linked, vec![true, true, true, false, false]);
    }

    #[test]
    fn groups_holding_masks_of_one_view_never_merge() {
        // Views: masks 0 and 1 in view 0, mask 2 in view 1. 0-2 link strongly, then 1-2.
        let mut hits = Vec::new();
        hits.extend(std::iter::repeat_n(vec![0, 2], 6));
        hits.extend(std::iter::repeat_n(vec![1, 2], 5));
        let grouping = group_by_shared_points(&[0, 0, 1], &hits, RULE);
        assert_eq!(grouping.groups, vec![vec![0, 2], vec![1]]);
        assert_eq!((grouping.merges, grouping.refused_merges), (1, 1));
    }

    #[test]
    fn links_must_be_a_share_of_the_smaller_mask() {
        // Masks 0 and 1 hold 18 points each and share 4 (22% < 30%): not one object.
        let mut hits = Vec::new();
        hits.extend(std::iter::repeat_n(vec![0, 1], 4));
        hits.extend(std::iter::repeat_n(vec![0], 14));
        hits.extend(std::iter::repeat_n(vec![1], 14));
        let grouping = group_by_shared_points(&[0, 1], &hits, RULE);
        assert_eq!(grouping.groups.len(), 2);
        // Six shared of 20 each (30%) are enough.
        hits.extend(std::iter::repeat_n(vec![0, 1], 2));
        assert_eq!(group_by_shared_points(&[0, 1], &hits, RULE).groups.len(), 1);
        // Masks of one view never link.
        assert_eq!(group_by_shared_points(&[0, 0], &hits, RULE).groups.len(), 2);
    }

    #[test]
    fn edge_points_fall_in_the_mask_beside_them() {
        let mut mask = BitMask::new(4, 4);
        mask.set(1, 1, true);
        mask.set(2, 1, true);
        let local = LocalMask {
            view: 0,
            bbox: mask.bounding_box().expect("non-empty"),
            area: mask.area(),
            mask,
        };
        let masks = [local];
        assert_eq!(masks_at(&masks, 0..1, [1.5, 1.5]), vec![0], "own pixel");
        // On the boundary between row 1 (set) and row 2 (empty), between columns 1 and 2.
        assert_eq!(masks_at(&masks, 0..1, [2.0, 2.0]), vec![0], "outline");
        assert!(
            masks_at(&masks, 0..1, [3.5, 3.5]).is_empty(),
            "a pixel away"
        );
    }
}
