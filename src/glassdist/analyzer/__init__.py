"""The Distortion Analyzer (paper §2.2): Block F (fourier, unwrap), Block I (homography), Block A (metrics)."""

from .captures import analyze_captures
from .fourier import Carrier, CarrierPair
from .homography import HomographyFit
from .metrics import Channels, channel_statistics, evaluate_displacement
from .params import AnalyzerParams, default_params_path, load_params
from .pipeline import ReferenceModel, analyze, prepare_reference
from .reflection import ReflectionGeometry, analyze_reflection
from .region import LABELS as QUALITY_LABELS
from .result import FIELDS, AnalysisResult, FieldSpec

__all__ = [
    "analyze",
    "analyze_captures",
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
