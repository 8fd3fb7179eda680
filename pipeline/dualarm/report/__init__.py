"""Reports from recordings: figures and markdown built only on the pandas read-back."""
