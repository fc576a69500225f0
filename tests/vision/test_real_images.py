"""The real-image set (real_scenes.py): what it is made of, and the detector on it.

Its figures per condition are the benchmark's (``benchmarks/bench_vision.py``) and the vision
README's; the tests hold what must never regress: no ball is ever found in the ball-free
photographs, and the set is the scene it says at every JPEG quality."""

from dataclasses import replace
import math

import cv2
import numpy as np
import pytest
from real_scenes import JPEG_QUALITIES, PHOTOS, ball_free_frame, photo, real_case

from inflarm_vision import tracker
from inflarm_vision.tracker import DetectorParams, detect_ball


def centre_error(case) -> float:
    """Distance of `detect_ball`'s centre from the truth [px]; inf where it finds no ball."""
    detection = detect_ball(case.image)
    return math.inf if detection is None else float(np.hypot(*(detection.center - case.center)))


def test_every_photograph_ships_in_an_installed_package_and_is_in_colour():
    for name in PHOTOS:
        image = photo(name)
        assert image.ndim == 3 and image.shape[2] == 3 and min(image.shape[:2]) >= 300, name
        # a photograph, not a flat image: its colours vary
        assert image.reshape(-1, 3).std(axis=0).min() > 10.0, name


def test_the_same_scene_comes_at_every_quality_with_the_ball_where_the_truth_says():
    for seed in range(6):
        cases = [real_case(seed, quality, occlusion=0.0) for quality in JPEG_QUALITIES]
        assert all(np.array_equal(c.center, cases[0].center) for c in cases)
        assert len({c.conditions.photo for c in cases}) == 1
        png = cases[0].image.astype(float)
        for case in cases[1:]:
            # JPEG changes the pixels a little, never the scene
            assert np.abs(case.image.astype(float) - png).mean() < 12.0
        # the ball's inner disc is yellow in HSV: hue 17-38 of OpenCV's 0-180 (34-76 deg)
        c, r = cases[0].center, cases[0].radius
        hsv = cv2.cvtColor(cases[0].image, cv2.COLOR_BGR2HSV)
        v, u = np.mgrid[:hsv.shape[0], :hsv.shape[1]]
        inner = np.hypot(u - c[0], v - c[1]) < 0.5 * r
        assert np.median(hsv[inner][:, 0]) == pytest.approx(27.0, abs=11.0)


@pytest.mark.parametrize('quality', JPEG_QUALITIES)
def test_no_ball_is_found_in_the_ball_free_photographs(quality):
    found = []
    for seed in range(30):
        detection = detect_ball(ball_free_frame(seed, quality))
        if detection is not None:
            found.append((seed, detection.center.round(1), round(detection.radius, 1)))
    assert found == []


def test_a_dull_orange_patch_under_jpeg_is_no_ball():
    # ball-free frame 42 at JPEG 50, the cat's fur: a round patch of 8 px whose pixels pass
    # the colour thresholds, of a colour of saturation 0.60 on average (a yellow ball's: 0.66
    # and more in the test set), was found on 64 % of its outline
    image = ball_free_frame(42, 50)
    assert detect_ball(image) is None
    found = detect_ball(image, DetectorParams(min_saturation=0.0))
    assert found is not None
    assert 0.55 < 1.0 - found.colour_bgr.min() / found.colour_bgr.max() < 0.63


def found_just_inside_the_border(occlusion: float) -> tuple[int, int]:
    """(found within 0.5 px, frames) of sharp 30 px balls of 24 scenes, their frames cut 2 and 4
    px right of the outline."""
    found, cases = 0, 0
    for seed in range(24):
        case = real_case(seed, None, radius_px=30.0, occlusion=occlusion, defocus_px=0.0,
                         motion_px=0.0)
        for gap_px in (2.0, 4.0):
            right = int(np.ceil(case.center[0] + case.radius + gap_px))
            if right >= case.image.shape[1]:
                continue
            detection = detect_ball(np.ascontiguousarray(case.image[:, :right]))
            cases += 1
            found += (detection is not None
                      and np.hypot(*(detection.center - case.center)) < 0.5)
    return found, cases


def test_a_ball_just_inside_the_image_border_is_found():
    # 2-4 px between its outline and the border: the windows beyond its edge are cut there
    found, cases = found_just_inside_the_border(0.0)
    assert cases >= 40 and found >= 0.9 * cases, (found, cases)  # 83 % before the cut windows


def test_a_ball_a_quarter_hidden_by_a_bar_just_inside_the_border_is_found():
    # the rays the border cuts short of the outline find no edge; with the bar's, they made too
    # long an arc off the outline, or two (42 of 47 found before they were left out)
    found, cases = found_just_inside_the_border(0.25)
    assert cases >= 40 and found >= cases - 1, (found, cases)


@pytest.mark.parametrize(('seed', 'quality'), [(234, 95), (109, 75), (299, 50)])
def test_a_ball_the_border_cuts_close_is_found(seed, quality):
    # held-out scenes: balls of 21, 84 and 16 px whose outlines come within 3-5 px of the
    # border, the first two a fifth hidden by a bar: missed before the rays the border cuts
    # short were left out where the outline's arcs are judged
    assert centre_error(real_case(seed, quality)) < 1.0


def test_a_ball_a_quarter_hidden_by_a_bar_is_found():
    found = 0
    for seed in range(60):
        case = real_case(seed, None, occlusion=0.25, radius_px=40.0, defocus_px=0.0,
                         motion_px=0.0)
        found += centre_error(case) < 1.0
    # 83 % before the coarse channel became the fine pass's last resort
    assert found >= 0.85 * 60, found


@pytest.mark.parametrize(('seed', 'quality'), [(185, None), (293, 75)])
def test_a_ball_hidden_by_a_bar_and_an_arc_of_texture_is_found(seed, quality, monkeypatch):
    # held-out scenes: balls of 28 px on grass and 85 px on coffee beans, 14 % and 28 % of the
    # outline hidden by a bar; the texture beside the bar takes a second arc off the outline,
    # which was refused as a bar of the ball's colour (two long runs of rays off it)
    case = real_case(seed, quality)
    assert case.conditions.occlusion > 0.1
    assert centre_error(case) < 0.5
    monkeypatch.setattr(tracker, '_TWO_RUNS_MIN_SHARE', math.inf)  # one hidden arc only
    assert centre_error(case) >= 1.0


def test_two_hidden_arcs_pass_for_a_ball_only_where_most_of_the_outline_is_found():
    on_outline = np.ones(100, bool)
    on_outline[5:23] = False  # 18 rays hidden by a bar
    on_outline[50:61] = False  # 11 by texture: 71 % on the outline
    assert tracker._one_hidden_arc(on_outline, 0.36)
    on_outline[61:64] = False  # 14 by texture: 68 %, as a bar of the ball's colour leaves
    assert not tracker._one_hidden_arc(on_outline, 0.36)
    on_outline[50:64] = True
    on_outline[5:37] = False  # one arc of 32 rays hidden
    assert tracker._one_hidden_arc(on_outline, 0.36)
    on_outline[37] = False  # 33 rays, 0.33 of them: more than 0.3 may not be hidden
    assert not tracker._one_hidden_arc(on_outline, 0.3)


@pytest.mark.parametrize(('seed', 'quality'), [(117, 75), (67, 95)])
def test_a_small_ball_whose_outline_the_first_channel_refuses_is_found_in_the_next(seed,
                                                                                  quality):
    # frames of the set: a ball of 6-7 px on the Hubble photograph's dark sky, in JPEG; the
    # ball-blind pass finds edges on 86 % of the rays and no ball in them, luma finds it
    # (missed while a refused outline on 85 % of the rays ended the search)
    case = real_case(seed, quality)
    assert case.conditions.photo == 'hubble' and case.radius < 7.5
    assert centre_error(case) < 1.0


@pytest.mark.parametrize('quality', [None, 75])
def test_a_ball_whose_colour_blob_is_smaller_than_it_is_found_from_a_larger_radius(
        quality, monkeypatch):
    # a held-out scene: a 56 px ball whose shaded limb falls below the colour thresholds, so
    # its blob covers about half its disc; the outline refined from the blob's radius is
    # refused, refined again from 1.3 times that radius it is found
    case = real_case(248, quality)
    blob = tracker._threshold(case.image, DetectorParams())  # the detector's colour mask
    v, u = np.mgrid[:blob.shape[0], :blob.shape[1]]
    disc = np.hypot(u - case.center[0], v - case.center[1]) <= case.radius
    assert np.count_nonzero(blob[disc]) < 0.6 * np.count_nonzero(disc)
    assert centre_error(case) < 1.0
    # without the second refinement the ball is missed
    monkeypatch.setattr(tracker, '_retry_min_confidence', lambda radius: 1.01)
    assert centre_error(case) >= 1.0


@pytest.mark.parametrize(('seed', 'quality'),
                         [(110, None), (110, 95), (222, 50), (303, 95), (316, 75)])
def test_a_ball_whose_blob_is_joined_by_threads_to_a_wider_one_is_found(seed, quality,
                                                                        monkeypatch):
    # a 26 px ball beside the space shuttle, joined by a thread 1 px wide to the external
    # tank's blob, which is wider than the ball; balls of 18 and 51 px on a cup's orange rim
    # and in a cat's eye, and of 5 px among gravel's specks, their blobs joined to the
    # surround's: each blob's largest disc is elsewhere, and the ball is found with the
    # threads of the colour mask cut
    case = real_case(seed, quality)
    mask = tracker._threshold(case.image, DetectorParams())
    _, labels, stats, _ = cv2.connectedComponentsWithStats(mask)
    u, v = (int(round(x)) for x in case.center + (0.8 * case.radius, 0.0))
    blob = stats[labels[v, u]]
    assert max(blob[cv2.CC_STAT_WIDTH], blob[cv2.CC_STAT_HEIGHT]) > 2.8 * case.radius
    assert centre_error(case) < 1.0
    # cutting nothing, the ball is missed (with the whole mask only: the mask without its
    # orange end separates the three larger balls too, not the small one)
    monkeypatch.setattr(tracker, '_THREAD_CUT', np.ones((1, 1), np.uint8))
    monkeypatch.setattr(tracker, '_ORANGE_HUES', 0)
    assert centre_error(case) == math.inf


@pytest.mark.parametrize('quality', [75, 50])
def test_a_ball_merged_with_a_thing_of_the_colour_masks_orange_end_is_found_without_it(
        quality, monkeypatch):
    # a held-out scene: an 18 px ball on a cup's foam, whose hues are the colour mask's lowest
    # (17-20); under JPEG no thread joins the ball's blob to the foam's, whose largest disc is
    # elsewhere; in the mask without its orange end, the ball's blob is its own
    case = real_case(303, quality)
    params = DetectorParams()
    yellow = replace(params, hsv_lower=(params.hsv_lower[0] + tracker._ORANGE_HUES,)
                     + params.hsv_lower[1:])
    u, v = (int(round(x)) for x in case.center + (0.8 * case.radius, 0.0))
    for mask_params, largest_disc_off in ((params, True), (yellow, False)):
        _, labels = cv2.connectedComponents(tracker._threshold(case.image, mask_params))
        distance = cv2.distanceTransform((labels == labels[v, u]).astype(np.uint8),
                                         cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
        peak = np.unravel_index(np.argmax(distance), distance.shape)[::-1]
        assert (np.hypot(*(peak - case.center)) > case.radius) == largest_disc_off
    assert centre_error(case) < 1.0
    # with the whole mask only, the ball is missed
    monkeypatch.setattr(tracker, '_ORANGE_HUES', 0)
    assert centre_error(case) == math.inf


@pytest.mark.parametrize(('seed', 'quality'), [(229, 75)])
def test_a_large_hidden_ball_is_believed_on_a_long_arc_of_its_outline(
        seed, quality, monkeypatch):
    # a held-out scene: a 111 px ball, 22 % of the outline hidden by a bar; the second
    # refinement finds 60-80 % of the outline, hundreds of px of arc, and a circle that long is
    # believed (scene 243, a 97 px ball, is found in the first round since the coarse pass only
    # places the fine one)
    case = real_case(seed, quality)
    assert case.radius > 80.0 and case.conditions.occlusion > 0.15
    detection = detect_ball(case.image)
    assert detection is not None
    assert np.hypot(*(detection.center - case.center)) < 1.0
    assert detection.radius == pytest.approx(case.radius, rel=0.02)
    assert 0.6 <= detection.confidence < tracker._RETRY_MIN_CONFIDENCE
    # asking 80 % of the outline of every size, as before, misses it
    monkeypatch.setattr(tracker, '_RETRY_MIN_ARC_PX', math.inf)
    assert centre_error(case) >= 1.0


@pytest.mark.parametrize(('seed', 'quality'), [(75, None), (295, 95)])
def test_a_small_blurred_ball_whose_rays_find_no_outline_is_found_from_its_whole_disc(
        seed, quality, monkeypatch):
    # held-out scenes: balls of 5-7 px, defocused; on their rays the blur leaves too few
    # samples for the edges' levels, and every candidate is refused (held-out 130 at JPEG 75 was
    # a third: 3 px from the border, its rays find it 0.64 px off since those the border cuts
    # are left out where its arcs are judged)
    case = real_case(seed, quality)
    assert case.radius < 7.5
    assert case.conditions.defocus_px > 0.0 or case.conditions.motion_px > 0.0
    detection = detect_ball(case.image)
    assert detection is not None
    assert np.hypot(*(detection.center - case.center)) < 0.5
    assert detection.radius == pytest.approx(case.radius, rel=0.2)
    # without the disc fit the ball is missed
    monkeypatch.setattr(tracker, '_DISC_MIN_CONFIDENCE', 1.01)
    assert centre_error(case) >= 1.0


@pytest.mark.parametrize(('seed', 'quality'), [(59, 50), (227, 50)])
def test_a_fine_outline_off_its_rough_centre_is_measured_again_from_its_own(seed, quality,
                                                                          monkeypatch):
    # a sharp 80 px ball (59, of the set) and a 24 px one blurred by motion (227, held out) at
    # JPEG 50: JPEG's chroma puts the rough centre a pixel off, and the fine outline from it
    # lands 1.0-1.1 px from the truth; measured again from its own centre, 0.2-0.3 px
    case = real_case(seed, quality)
    assert centre_error(case) < 0.5
    monkeypatch.setattr(tracker, '_FINE_REPEATS', 0)
    # nor polished (`_polish` gets 59 within 0.6 px too)
    monkeypatch.setattr(tracker, '_POLISH_MAX_MOVE_PX', 0.0)
    assert centre_error(case) >= 1.0


@pytest.mark.parametrize(('seed', 'quality'), [(162, 75), (301, 75)])
def test_a_ball_of_8_to_12_px_whose_rays_fail_is_found_from_its_whole_disc(seed, quality,
                                                                         monkeypatch):
    # held-out scenes at JPEG 75: balls of 8-10 px defocused by 2.2 px and 22 % hidden (162)
    # or blurred by a 5.7 px motion (301): their candidates are 8 px or more, where the disc
    # fit was not tried (scene 152 is found without it since the coarse pass only places the
    # fine one: from the larger radius)
    case = real_case(seed, quality)
    assert 8.0 < case.radius < 12.0
    assert centre_error(case) < 0.5
    monkeypatch.setattr(tracker, '_DISC_MAX_RADIUS_PX', 8.0)
    assert centre_error(case) >= 1.0


@pytest.mark.parametrize(('seed', 'quality'), [(284, 75), (284, None), (72, None)])
def test_a_whole_outline_just_under_the_smallest_radius_is_a_ball(seed, quality, monkeypatch):
    # balls of 4.1-4.3 px (the spec's smallest: 4) whose whole outline is found 0.4 px from
    # the truth, with a radius of 3.9-4.0 px
    case = real_case(seed, quality)
    assert case.radius < 4.5
    assert centre_error(case) < 0.5
    assert detect_ball(case.image).radius < DetectorParams().min_radius_px
    monkeypatch.setattr(tracker, '_RADIUS_TOLERANCE_PX', 0.0)
    assert centre_error(case) >= 1.0


@pytest.mark.parametrize(('seed', 'quality'), [(36, 75), (196, 75), (246, 75), (296, 75)])
def test_a_ball_on_gravel_is_refined_beside_the_specks_that_outrank_it(seed, quality,
                                                                      monkeypatch):
    # balls of 12-25 px on the gravel photograph, whose hundreds of yellowish specks of 3-5 px
    # are as round and as vivid as a ball; the ball's blob merged with some of them, so only
    # its inscribed disc is a candidate, and it ranks 5th or 6th: the best large candidate is
    # refined beside the best four
    case = real_case(seed, quality)
    assert case.conditions.photo == 'gravel' and case.radius > 12.0
    assert centre_error(case) < 1.0
    # refining only the best four, as before, misses it (without the last round as well,
    # whose large candidates leave the specks out)
    candidates = tracker._candidates
    monkeypatch.setattr(tracker, '_candidates', lambda *args, **kw: candidates(*args, **kw)[:4])
    monkeypatch.setattr(tracker, '_NEW_CANDIDATE', math.inf)
    assert centre_error(case) >= 1.0


@pytest.mark.parametrize(('seed', 'quality'), [(60, 75), (309, None)])
def test_a_small_ball_blurred_by_half_its_radius_is_found_from_its_whole_disc(seed, quality,
                                                                             monkeypatch):
    # balls of 4.4 px blurred by a 6 px motion (60, of the set) and of 5.0 px defocused by
    # 1.8 px and 23 % hidden (309, held out): the disc fit measures a blur of 0.51 and 0.40
    # of the radius, just above the 0.4 it allowed
    case = real_case(seed, quality)
    assert case.radius < 5.5
    assert centre_error(case) < 0.5
    # with that bound, and the profile tolerance it was measured with (a fit held at a blur of
    # 0.4 strays from the rays' profiles by more), missed
    monkeypatch.setattr(tracker, '_DISC_MAX_BLUR', 0.4)
    monkeypatch.setattr(tracker, '_DISC_PROFILE_TOLERANCE', tracker._DISC_ORANGE_PROFILE_TOLERANCE)
    assert centre_error(case) >= 1.0


def test_a_large_ball_outweighs_a_speck_whose_whole_outline_is_found():
    # scene 116 at JPEG 75 (of the set): a 96 px ball on gravel, found on 95 of its 96 rays,
    # and a sand speck found on all 32 of its own; the larger share of rays picked the speck
    # (a speck too pale for min_saturation now: without that floor it is accepted)
    case = real_case(116, 75)
    params = DetectorParams(min_saturation=0.0)
    detection = detect_ball(case.image, params)
    assert np.hypot(*(detection.center - case.center)) < 0.5
    assert detection.radius == pytest.approx(case.radius, abs=1.0)
    speck = tracker._refine(case.image, np.array([202.6, 9.3]), 2.6, params,
                            0.25 * 2.6 + params.decimation)
    assert tracker._accept(speck, params) and speck.radius < 5.0
    assert speck.confidence > detection.confidence
    assert len(speck.edge_points) < len(detection.edge_points)


@pytest.mark.parametrize(('seed', 'quality'), [(6, 75), (223, 75), (223, 50), (224, 75)])
def test_a_coarse_outline_whose_rays_fall_off_it_in_two_arcs_still_places_the_fine_pass(
        seed, quality, monkeypatch):
    # balls of 10-18 px at JPEG 50-75 (6 on gravel, of the set; 223 on coffee, 24 % hidden by a
    # bar, and 224 on grace_hopper, 26 % hidden, held out): from the candidate's rough centre
    # the coarse pass finds 60-70 % of the outline, with the rays off it in arcs that
    # `_one_hidden_arc` refuses; the fine pass from that outline's centre finds the ball
    case = real_case(seed, quality)
    assert 10.0 <= case.radius < 18.0
    assert centre_error(case) < 0.6
    # a coarse outline judged like the fine one, as before, places no fine pass: missed
    refine_at = tracker._refine_at
    monkeypatch.setattr(tracker, '_refine_at',
                        lambda *args, placing=False, **kw: refine_at(*args, **kw))
    assert centre_error(case) >= 1.0


@pytest.mark.parametrize(('seed', 'quality'), [(6, 95), (76, 75), (185, 75)])
def test_an_outline_in_jpeg_is_polished_with_luma_at_the_chroma_resolution(seed, quality,
                                                                           monkeypatch):
    # balls of 14, 142 and 28 px (gravel, gravel, grass) whose accepted outline was 1.06-1.4 px
    # off in JPEG: its ball-blind channel sums a sharp luma step and a chroma step JPEG made
    # twice as wide; measured again with the luma at the chroma's resolution, within 1 px
    case = real_case(seed, quality)
    assert centre_error(case) < 1.0
    # unpolished (no move allowed), as before
    monkeypatch.setattr(tracker, '_POLISH_MAX_MOVE_PX', 0.0)
    assert 1.0 <= centre_error(case) < 1.5


@pytest.mark.parametrize(('seed', 'quality'), [(125, 75), (266, 50)])
def test_tracking_polishes_the_outline_as_the_search_does(seed, quality, monkeypatch):
    # the tracking pass (the last outline refined in place; balls of 24 and 21 px on grass and
    # gravel) ends as the search does: unpolished, 1.1-1.8 px off
    case = real_case(seed, quality)
    for max_move_px, within in ((tracker._POLISH_MAX_MOVE_PX, True), (0.0, False)):
        monkeypatch.setattr(tracker, '_POLISH_MAX_MOVE_PX', max_move_px)
        ball_tracker = tracker.BallTracker()
        ball_tracker.update(case.image)
        second = ball_tracker.update(case.image)
        assert ball_tracker.full_frame_searches == 1 and ball_tracker.region_searches == 0
        assert (np.hypot(*(second.center - case.center)) < 1.0) == within


@pytest.mark.parametrize(('seed', 'quality'), [(80, None), (80, 75), (168, 95), (178, 75)])
def test_a_small_ball_of_which_the_colour_mask_holds_a_few_pixels_is_found(seed, quality,
                                                                            monkeypatch):
    # balls of 4.3-4.7 px: dark (exposure 0.5) on grey and on a retina's red, their shaded
    # part under the colour thresholds, and defocused on the retina's orange, their rim blurred
    # into it; at the candidates' scale the mask holds 6-9 of their pixels, under the area of
    # the smallest ball's disc within the blob's contour
    case = real_case(seed, quality)
    assert case.radius < 5.0
    assert centre_error(case) < 1.0
    # without the blobs of a few pixels, missed
    monkeypatch.setattr(tracker, '_tiny_candidates', lambda *args, **kwargs: [])
    assert centre_error(case) == math.inf


@pytest.mark.parametrize(('seed', 'quality'), [(146, 50), (210, 50), (370, 75), (473, 75)])
def test_a_speck_of_a_few_pixels_is_a_ball_only_where_its_colour_stands_out(seed, quality,
                                                                            monkeypatch):
    # ball-free frames (gravel, a face, a cup): specks of a few pixels of the ball's colour
    # whose outline passes for a ball's, but whose colour stands out from its surround by
    # less than the small balls' above (3.2-4.2 of their spreads, the balls' 6.5-9.2)
    image = ball_free_frame(seed, quality)
    assert detect_ball(image) is None
    monkeypatch.setattr(tracker, '_TINY_MIN_SEPARATION', 0.0)
    detection = detect_ball(image)
    assert detection is not None and detection.radius < 7.0


@pytest.mark.parametrize(('seed', 'quality'), [(46, 95), (156, 95), (189, 75), (142, 50)])
def test_a_small_ball_whose_rays_stray_from_the_blurred_disc_is_found_from_it(seed, quality,
                                                                           monkeypatch):
    # balls of 4-7 px on gravel and on a cat, in motion blur (not the Gaussian of the disc's
    # model) or defocused, under JPEG: 7-9 of their 32 rays' profiles are 0.2-0.35 of the
    # edge's step off the fitted disc's, which leaves less than 80 % of the rays agreeing
    case = real_case(seed, quality)
    assert case.radius < 7.0
    assert centre_error(case) < 1.0
    # with the tolerance of a disc at the orange end of the colour mask, missed
    monkeypatch.setattr(tracker, '_DISC_PROFILE_TOLERANCE', tracker._DISC_ORANGE_PROFILE_TOLERANCE)
    assert centre_error(case) == math.inf


@pytest.mark.parametrize(('seed', 'quality'), [(66, 75), (450, 50), (740, 50), (1280, 50)])
def test_an_orange_speck_must_fit_the_blurred_disc_closely(seed, quality, monkeypatch):
    # ball-free frames: specks of the mask's orange end (hue 17-20; the yellow ball's are 21 and
    # above) whose whole disc fits the blurred disc's model within the yellow ball's tolerance
    image = ball_free_frame(seed, quality)
    assert detect_ball(image) is None
    monkeypatch.setattr(tracker, '_ORANGE_HUES', 0)
    detection = detect_ball(image)
    assert detection is not None and detection.radius < 7.0
