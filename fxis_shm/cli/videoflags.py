"""The video flags ``fxis record`` and ``fxis snapshot`` share: --codec and its settings
(fxis_shm.formats.videotracks), checked before a service is asked."""

from __future__ import annotations

from fxis_shm.errors import ConfigError
from fxis_shm.formats.videochoice import CODECS, split_encoding

ENCODINGS = ("raw", "jpeg", *CODECS)  # --encoding: images, or a video codec as --codec names it


def add_encoding_option(parser, images: str) -> None:
    """--encoding: ``images`` says what raw and jpeg write; a codec's name is --codec's."""
    parser.add_argument(
        "--encoding", choices=ENCODINGS, default="raw", help=f"{images}; h264, h265, av1: video, as --codec"
    )


def add_video_options(parser, what: str) -> None:
    """--codec, --encoder, --crf, --preset, --gop; ``what``: the frames they encode."""
    parser.add_argument(
        "--codec",
        metavar="C",
        help=f"{what} as video instead: h264, h265 or av1, as foxglove_msgs/CompressedVideo on /NAME/video "
        "(one frame per message, stamped with its capture time) and each frame's id on /NAME/video/frames",
    )
    parser.add_argument(
        "--encoder",
        metavar="E",
        help="auto (default: a hardware encoder, NVENC, VAAPI or QSV, if one opens, else software), "
        "software, or an FFmpeg encoder's name (libx264, h264_nvenc, ...)",
    )
    parser.add_argument("--crf", type=int, metavar="N", help="quality: lower is better and bigger (default per codec)")
    parser.add_argument("--preset", metavar="P", help="the encoder's speed preset (default veryfast for libx264)")
    parser.add_argument("--gop", type=float, metavar="S", help="a keyframe at least every S seconds (default 2)")


def video_settings(args):
    """The VideoSettings the flags ask for (None: no --codec), or ConfigError naming the flag."""
    from fxis_shm.formats.videotracks import VideoSettings, check_flags

    given = [f for f, v in (("--encoder", args.encoder), ("--crf", args.crf), ("--preset", args.preset)) if v]
    given += ["--gop"] if args.gop is not None else []
    image_encoding, codec = split_encoding(args.encoding, args.codec, "--")
    if codec is None:
        if given:
            raise ConfigError(f"{', '.join(given)} apply to video only: give --codec h264, h265 or av1")
        return None
    if image_encoding != "raw" or getattr(args, "quality", None) is not None:
        raise ConfigError(f"--codec {codec} records video: it takes no --encoding {image_encoding} or --quality")
    video = VideoSettings(codec, args.encoder or "auto", args.crf, args.preset, args.gop)
    check_flags(video)
    return video
