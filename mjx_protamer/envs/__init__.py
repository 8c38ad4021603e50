"""The self-touch environment: body model, touch, regions, reward, MJX env and NumPy twin."""
