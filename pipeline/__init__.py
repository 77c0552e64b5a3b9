"""objsearch.pipeline"""
