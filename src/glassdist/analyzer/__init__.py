"""The Distortion Analyzer (paper §2.2): Block F (fourier, unwrap), Block I (homography), Block A (metrics)."""

from .._lazy import lazy_exports

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
