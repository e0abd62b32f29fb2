"""Outputs of a fit: the files of a fit directory and the report rendered from them."""

from .report import render_report as render_report
