"""Human-readable reports of fits: report.html per fit, index.html per batch."""
