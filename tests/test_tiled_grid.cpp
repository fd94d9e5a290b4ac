// TiledGrid and GridGeometry: conversions at negative coordinates and tile borders, lazy tiles,
// the cell budget.

#include <gtest/gtest.h>

#include <map>
#include <random>

#include "lidar2d/core/error.hpp"
#include "lidar2d/mapping/tiled_grid.hpp"

namespace lidar2d::mapping {
namespace {

TEST(GridGeometry, CellOfUsesFloorAtNegativeCoordinates) {
  const GridGeometry g(0.05);
  EXPECT_EQ(g.cellOf({0.0, 0.0}), (CellIndex{0, 0}));
  EXPECT_EQ(g.cellOf({0.0499, 0.05}), (CellIndex{0, 1}));
  EXPECT_EQ(g.cellOf({-0.0001, -0.05}), (CellIndex{-1, -1}));
  EXPECT_EQ(g.cellOf({-0.0501, 3.2}), (CellIndex{-2, 64}));
  EXPECT_EQ(g.cellOf({-3.2, -3.2001}), (CellIndex{-64, -65}));
  // Centres map back to their cell, for many cells on both sides of 0 and across tile borders.
  for (int x = -200; x <= 200; x += 7)
    for (int y = -130; y <= 130; y += 13) EXPECT_EQ(g.cellOf(g.centerOf({x, y})), (CellIndex{x, y}));
}

TEST(GridGeometry, RejectsBadResolution) {
  for (double r : {0.0, -0.05, 1e-9, 1e6, std::nan("")}) {
    try {
      GridGeometry g(r);
      ADD_FAILURE() << "accepted " << r;
    } catch (const Error& e) {
      EXPECT_EQ(e.where().field, "resolution");
    }
  }
}

TEST(TiledGrid, StoresAcrossTileBordersAndNegativeIndices) {
  TiledGrid<int> grid(-7, 1'000'000);
  EXPECT_EQ(grid.get({5, 5}), -7);
  std::mt19937 rng(3);
  std::uniform_int_distribution<int> d(-300, 300);
  std::vector<std::pair<CellIndex, int>> written;
  for (int i = 0; i < 2000; ++i) {
    const CellIndex c{d(rng), d(rng)};
    grid.at(c) = i;
    written.emplace_back(c, i);
  }
  // Tile borders explicitly: 63/64 and -1/0 and -64/-65.
  for (int v : {-65, -64, -1, 0, 63, 64}) {
    grid.at({v, 17}) = 1000 + v;
    written.emplace_back(CellIndex{v, 17}, 1000 + v);
  }
  // Last write wins; replay to get the expected value per cell.
  std::map<std::pair<int, int>, int> expected;
  for (const auto& [c, v] : written) expected[{c.x, c.y}] = v;
  for (const auto& [k, v] : expected) EXPECT_EQ(grid.get({k.first, k.second}), v);
  EXPECT_EQ(grid.get({10000, 10000}), -7);
  EXPECT_FALSE(grid.isAllocated({10000, 10000}));
  const CellBox box = grid.allocatedBox();
  EXPECT_LE(box.min.x, -300);
  EXPECT_GE(box.max.x, 300);
  EXPECT_EQ(box.min.x % 64, 0);
}

TEST(TiledGrid, CursorGivesTheSameCellsAsTheTableAcrossTilesAndGrowth) {
  TiledGrid<int> grid(0, 200'000'000);
  grid.reserve(CellBox{{-200, -200}, {200, 200}});
  TiledGrid<int>::Cursor cursor;
  // A walk crossing tile borders both ways, at negative indices too.
  std::vector<CellIndex> cells;
  for (int x = -150; x <= 150; ++x) cells.push_back({x, x / 3 - 20});
  for (int y = 150; y >= -150; --y) cells.push_back({-65, y});
  int i = 1;
  for (const CellIndex& c : cells) grid.cellCached(c, cursor) = i++;
  // The table grows (moves the tile pointers, not the tiles): the cursor keeps working.
  grid.reserve(CellBox{{-5000, -5000}, {5000, 5000}});
  grid.cellCached({-65, 150}, cursor) += 1000000;
  i = 1;
  std::map<std::pair<int, int>, int> expected;
  for (const CellIndex& c : cells) expected[{c.x, c.y}] = i++;
  expected[{-65, 150}] += 1000000;
  for (const auto& [k, v] : expected) {
    EXPECT_EQ(grid.get({k.first, k.second}), v) << k.first << "," << k.second;
    EXPECT_EQ(&grid.cellUnchecked({k.first, k.second}), &grid.cellCached({k.first, k.second}, cursor));
  }
}

TEST(TiledGrid, AllocatesTilesLazily) {
  TiledGrid<float> grid(0.0f, 100'000'000);
  grid.reserve(CellBox{{-1000, -1000}, {1000, 1000}});
  EXPECT_EQ(grid.numTiles(), 0u);
  grid.cellUnchecked({-1000, -1000}) = 1;
  grid.cellUnchecked({999, 999}) = 1;
  grid.cellUnchecked({998, 998}) = 1;
  EXPECT_EQ(grid.numTiles(), 2u);
  EXPECT_EQ(grid.numAllocatedCells(), 2u * 64 * 64);
  int tiles = 0;
  grid.forEachTile([&](CellIndex origin, const float*) {
    EXPECT_EQ(origin.x % 64, 0);
    ++tiles;
  });
  EXPECT_EQ(tiles, 2);
}

TEST(TiledGrid, CellBudgetTurnsAbsurdExtentsIntoAnError) {
  TiledGrid<float> grid(0.0f, 1'000'000);
  grid.at({0, 0}) = 1;
  try {
    grid.at({100'000'000, 0}) = 1;
    ADD_FAILURE() << "no error";
  } catch (const Error& e) {
    EXPECT_EQ(e.where().field, "extent");
    EXPECT_NE(std::string(e.what()).find("budget"), std::string::npos);
  }
  // The failed call left the grid usable.
  EXPECT_EQ(grid.get({0, 0}), 1.0f);
}

}  // namespace
}  // namespace lidar2d::mapping
