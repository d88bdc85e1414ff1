// pbr_lod — PCL peers (peers/pcl_simplify.hpp). Built into pbr_lod::peers_pcl only when PCL is
// found (src/peers/peers.cmake).
#include "pbr_lod/peers/pcl_simplify.hpp"

#include <pcl/filters/voxel_grid.h>
#include <pcl/octree/octree_pointcloud_pointvector.h>
#include <pcl/point_types.h>

#include <cmath>
#include <string>

#include "pbr_lod/core/error.hpp"

namespace pbr_lod::peers {
namespace {
using pcl_point = pcl::PointXYZRGBNormal;
using pcl_cloud = pcl::PointCloud<pcl_point>;

void check_size(const char* what, double s) {
  if (!(s > 0) || !std::isfinite(s))
    throw InvalidArgument(std::string(what) + ": the cell size must be positive and finite, got " +
                          std::to_string(s));
}

pcl_cloud::Ptr to_pcl(const point_cloud& in) {
  auto out = pcl_cloud::Ptr(new pcl_cloud);
  out->resize(in.size());
  for (std::size_t i = 0; i < in.size(); ++i) {
    pcl_point& p = (*out)[i];
    p.x = in.positions[i].x(), p.y = in.positions[i].y(), p.z = in.positions[i].z();
    const vec3f n = in.normals.empty() ? vec3f::Zero() : in.normals[i];
    p.normal_x = n.x(), p.normal_y = n.y(), p.normal_z = n.z();
    const rgb8 c = in.colours.empty() ? rgb8{} : in.colours[i];
    p.r = c.r, p.g = c.g, p.b = c.b, p.a = 255;
  }
  return out;
}

/// Back to a cloud with the input's origin and the attributes the input had; averaged normals
/// are renormalised (a voxel whose normals cancel gets the first axis: a splat still needs one).
point_cloud from_pcl(const pcl_cloud& c, const point_cloud& like) {
  point_cloud out;
  out.origin = like.origin;
  out.sensor = like.sensor;
  for (const pcl_point& p : c) {
    out.positions.emplace_back(p.x, p.y, p.z);
    if (!like.normals.empty()) {
      const vec3f n(p.normal_x, p.normal_y, p.normal_z);
      out.normals.push_back(n.norm() > 1e-6f ? vec3f(n.normalized()) : vec3f::UnitX());
    }
    if (!like.colours.empty()) out.colours.push_back({p.r, p.g, p.b});
  }
  return out;
}

}  // namespace

point_cloud pcl_voxel_grid(const point_cloud& in, double leaf) {
  check_size("pcl_voxel_grid", leaf);
  in.validate("pcl_voxel_grid: input");
  if (in.empty()) return from_pcl(pcl_cloud{}, in);
  // VoxelGrid indexes voxels with 32 bits and only warns (returning the input) past that.
  vec3f lo = in.positions[0], hi = lo;
  for (const auto& p : in.positions) lo = lo.cwiseMin(p), hi = hi.cwiseMax(p);
  const vec3d cells = ((hi - lo).cast<double>() / leaf).array().floor() + 1;
  if (cells.x() * cells.y() * cells.z() > 2147483647.0)
    throw InvalidArgument("pcl_voxel_grid: leaf " + std::to_string(leaf) +
                          " is too small for PCL's 32-bit voxel index over this cloud");
  pcl::VoxelGrid<pcl_point> grid;
  grid.setInputCloud(to_pcl(in));
  const float l = static_cast<float>(leaf);
  grid.setLeafSize(l, l, l);
  pcl_cloud out;
  grid.filter(out);
  return from_pcl(out, in);
}

point_cloud pcl_octree_centroids(const point_cloud& in, double resolution) {
  check_size("pcl_octree_centroids", resolution);
  in.validate("pcl_octree_centroids: input");
  if (in.empty()) return from_pcl(pcl_cloud{}, in);
  // The octree's leaves hold point indices; the mean of each leaf's points is taken here, not
  // by OctreePointCloudVoxelCentroid, whose centroid container sums PointT with PCL's point
  // arithmetic and so adds the packed RGB field as a float (wrong colours for RGB types).
  auto xyz = pcl::PointCloud<pcl::PointXYZ>::Ptr(new pcl::PointCloud<pcl::PointXYZ>);
  xyz->resize(in.size());
  for (std::size_t i = 0; i < in.size(); ++i)
    (*xyz)[i] = {in.positions[i].x(), in.positions[i].y(), in.positions[i].z()};
  pcl::octree::OctreePointCloudPointVector<pcl::PointXYZ> octree(resolution);
  octree.setInputCloud(xyz);
  octree.addPointsFromInputCloud();
  pcl_cloud out;
  for (auto it = octree.leaf_depth_begin(); it != octree.leaf_depth_end(); ++it) {
    const auto& indices = it.getLeafContainer().getPointIndicesVector();
    if (indices.empty()) continue;
    vec3d p = vec3d::Zero(), n = vec3d::Zero(), c = vec3d::Zero();
    for (const auto i : indices) {
      const auto k = static_cast<std::size_t>(i);
      p += in.positions[k].cast<double>();
      if (!in.normals.empty()) n += in.normals[k].cast<double>();
      if (!in.colours.empty()) c += vec3d(in.colours[k].r, in.colours[k].g, in.colours[k].b);
    }
    const double m = static_cast<double>(indices.size());
    pcl_point q;
    q.x = static_cast<float>(p.x() / m), q.y = static_cast<float>(p.y() / m),
    q.z = static_cast<float>(p.z() / m);
    q.normal_x = static_cast<float>(n.x()), q.normal_y = static_cast<float>(n.y()),
    q.normal_z = static_cast<float>(n.z());
    const auto channel = [&](double v) { return static_cast<std::uint8_t>(std::lround(v / m)); };
    q.r = channel(c.x()), q.g = channel(c.y()), q.b = channel(c.z());
    out.push_back(q);
  }
  return from_pcl(out, in);
}

}  // namespace pbr_lod::peers
