"""What every part of Aisle needs: settings, message types, the zenoh bus and the map store."""
