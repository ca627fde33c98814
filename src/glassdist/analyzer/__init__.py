"""The Distortion Analyzer (paper §2.2): Block F (fourier, unwrap), Block I (homography), Block A (metrics)."""

from typing import TYPE_CHECKING

from .._lazy import lazy_exports

# --- typed names for static tools (scripts/lazy_stubs.py writes this block) ---
if TYPE_CHECKING:
    from .calibrate import calibrate_from_photo
    from .captures import analyze_captures
    from .fourier import Carrier, CarrierPair
    from .homography import HomographyFit
    from .metrics import Channels, channel_statistics, evaluate_displacement
    from .params import AnalyzerParams, default_params_path, load_params
    from .pipeline import ReferenceModel, analyze, prepare_reference
    from .reflection import ReflectionGeometry, analyze_reflection
    from .region import LABELS as QUALITY_LABELS
    from .result import FIELDS, AnalysisResult, FieldSpec
# --- end of the typed names ---

# loaded on first use: checking a command's inputs needs the parameters, not the analysis stack
__getattr__, __dir__ = lazy_exports(__name__, {
    "analyze_captures": ".captures",
    "calibrate_from_photo": ".calibrate",
    "Carrier": ".fourier", "CarrierPair": ".fourier",
    "HomographyFit": ".homography",
    "Channels": ".metrics", "channel_statistics": ".metrics", "evaluate_displacement": ".metrics",
    "AnalyzerParams": ".params", "default_params_path": ".params", "load_params": ".params",
    "ReferenceModel": ".pipeline", "analyze": ".pipeline", "prepare_reference": ".pipeline",
    "ReflectionGeometry": ".reflection", "analyze_reflection": ".reflection",
    "QUALITY_LABELS": ".region:LABELS",
    "FIELDS": ".result", "AnalysisResult": ".result", "FieldSpec": ".result",
})

__all__ = [
    "analyze",
    "analyze_captures",
    "calibrate_from_photo",
    "analyze_reflection",
    "ReflectionGeometry",
    "prepare_reference",
    "AnalysisResult",
    "FIELDS",
    "FieldSpec",
    "ReferenceModel",
    "AnalyzerParams",
    "load_params",
    "default_params_path",
    "evaluate_displacement",
    "channel_statistics",
    "Channels",
    "Carrier",
    "CarrierPair",
    "HomographyFit",
    "QUALITY_LABELS",
]
