"""Which encoder ``fxis record --codec`` uses, and the settings it refuses (fxis_shm.formats.videochoice).
Hardware is absent here, so which encoders open is a parameter of the choice."""

import pytest

from fxis_shm.errors import ConfigError
from fxis_shm.formats import videochoice as vc

EVERYTHING = {"libx264", "libx265", "libsvtav1", "h264_nvenc", "h264_vaapi", "h264_qsv", "hevc_nvenc", "av1_qsv"}


def test_auto_takes_the_first_hardware_encoder_that_opens():
    choice = vc.choose("h264", vc.AUTO, EVERYTHING, opens=lambda name: name == "h264_vaapi")
    assert choice == vc.Choice("h264", "h264_vaapi", hardware=True)
    assert choice.describe() == "h264 with h264_vaapi (hardware)"


def test_auto_tries_nvenc_vaapi_qsv_then_falls_back_to_software():
    tried = []
    choice = vc.choose("h264", vc.AUTO, EVERYTHING, opens=lambda name: tried.append(name) or name == "libx264")
    assert tried == ["h264_nvenc", "h264_vaapi", "h264_qsv", "libx264"]
    assert choice == vc.Choice("h264", "libx264", hardware=False)


def test_auto_skips_encoders_the_bundled_ffmpeg_lacks():
    tried = []
    choice = vc.choose("av1", vc.AUTO, EVERYTHING, opens=lambda name: tried.append(name) or True)
    assert tried == ["av1_qsv"] and choice.hardware


def test_software_never_tries_hardware():
    tried = []
    choice = vc.choose("h265", vc.SOFTWARE, EVERYTHING, opens=lambda name: tried.append(name) or True)
    assert tried == ["libx265"] and choice == vc.Choice("h265", "libx265", hardware=False)


def test_a_named_encoder_is_the_only_one_tried():
    assert vc.candidates("h264", "h264_qsv") == ["h264_qsv"]
    with pytest.raises(ConfigError, match="h264_qsv would not open"):
        vc.choose("h264", "h264_qsv", EVERYTHING, opens=lambda name: False)


@pytest.mark.parametrize(
    "codec, encoder, words",
    [
        ("vp8", vc.AUTO, ["--codec vp8", "h264, h265, av1"]),
        ("h264", "libx265", ["--encoder libx265", "libx264", "h264_nvenc"]),
        ("h264", "magic", ["--encoder magic", "auto, software"]),
    ],
)
def test_unknown_codecs_and_encoders_are_refused_naming_what_there_is(codec, encoder, words):
    with pytest.raises(ConfigError) as caught:
        vc.candidates(codec, encoder)
    assert all(w in str(caught.value) for w in words), caught.value


def test_a_codec_the_bundled_ffmpeg_lacks_is_refused():
    with pytest.raises(ConfigError, match="needs .*libsvtav1; the bundled FFmpeg has none of them"):
        vc.choose("av1", vc.AUTO, {"libx264"}, opens=lambda name: True)


def test_crf_defaults_per_codec_and_is_refused_out_of_range():
    assert [vc.check_crf(c, None) for c in vc.CODECS] == [23, 28, 35]
    assert vc.check_crf("h264", 0) == 0 and vc.check_crf("av1", 63) == 63
    for codec, crf in (("h264", 52), ("h264", -1), ("av1", 0), ("av1", 64)):
        with pytest.raises(ConfigError, match=f"--crf {crf}: out of range for {codec}"):
            vc.check_crf(codec, crf)


def test_gop_defaults_to_two_seconds_and_is_refused_out_of_range():
    assert vc.check_gop(None) == 2.0 and vc.check_gop(0.1) == 0.1 and vc.check_gop(60) == 60
    for gop in (0.0, 0.05, 61.0):
        with pytest.raises(ConfigError, match="--gop .*from 0.1 to 60"):
            vc.check_gop(gop)


def test_presets_default_per_encoder_and_unknown_ones_are_refused():
    x264 = vc.Choice("h264", "libx264", False)
    assert vc.check_preset(x264, None) == "veryfast" and vc.check_preset(x264, "ultrafast") == "ultrafast"
    assert vc.check_preset(vc.Choice("h264", "h264_nvenc", True), None) is None  # the hardware's own
    with pytest.raises(ConfigError, match="--preset quick: not a preset of libx264; one of ultrafast"):
        vc.check_preset(x264, "quick")
    with pytest.raises(ConfigError, match="one of 0, 1"):
        vc.check_preset(vc.Choice("av1", "libsvtav1", False), "14")


def test_only_8_bit_frames_of_even_size_are_carried():
    for encoding in ("mono8", "bgr8", "bgra8"):
        vc.check_camera("h264", "cam", encoding, 1360, 1024)
    with pytest.raises(ConfigError, match="camera depth gives mono16 frames.*carries mono8, bgr8"):
        vc.check_camera("h264", "depth", "mono16", 640, 480)
    with pytest.raises(ConfigError, match="camera odd is 161x120; 4:2:0 video needs an even width"):
        vc.check_camera("h265", "odd", "mono8", 161, 120)


def test_an_encoding_that_names_a_codec_is_that_codec():
    assert vc.split_encoding("h264", None) == ("raw", "h264")  # encoding="h264", the spelling
    assert vc.split_encoding("av1", "av1") == ("raw", "av1")
    assert vc.split_encoding("jpeg", None) == ("jpeg", None)
    assert vc.split_encoding("raw", "h265") == ("raw", "h265")
    assert vc.split_encoding("jpeg", "h264") == ("jpeg", "h264")  # refused later: video takes no jpeg
    with pytest.raises(ConfigError, match="^--encoding h264 and --codec h265 disagree"):
        vc.split_encoding("h264", "h265", "--")
