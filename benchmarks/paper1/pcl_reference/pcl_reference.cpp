// PCL 1.13 reference descriptors for relnav's tests (see regenerate.py for the file formats).
//
// Usage: pcl_reference IN.bin OUT.bin
// IN:  int32 N, K, spin_width; float32 radius, gp3_radius, gp3_mu; N x 6 float32 (x y z nx ny nz);
//      K int32 keypoint indices; int32 M, then K + 1 int32 offsets and M x 3 int32 vertex indices:
//      the local triangles of each keypoint (CSR, relnav's rops_local_mesh).
// OUT: for spin, rops, fpfh, shot, triangles, rops_local in turn: int32 rows, cols, then
//      rows x cols values (float32; int32 for the triangles). rops_local row k is ROPSEstimation
//      at keypoint k alone (search surface = the whole cloud) with keypoint k's local triangles
//      as the mesh; NaN when it has none.
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <fstream>
#include <iostream>
#include <limits>
#include <vector>

#include <pcl/features/fpfh.h>
#include <pcl/features/rops_estimation.h>
#include <pcl/features/shot.h>
#include <pcl/features/spin_image.h>
#include <pcl/point_cloud.h>
#include <pcl/point_types.h>
#include <pcl/search/kdtree.h>
#include <pcl/surface/gp3.h>

template <typename T>
static void write_block(std::ofstream& out, int32_t rows, int32_t cols, const std::vector<T>& v) {
  out.write(reinterpret_cast<const char*>(&rows), sizeof rows);
  out.write(reinterpret_cast<const char*>(&cols), sizeof cols);
  out.write(reinterpret_cast<const char*>(v.data()), sizeof(T) * v.size());
}

int main(int argc, char** argv) {
  if (argc != 3) {
    std::cerr << "usage: pcl_reference IN.bin OUT.bin\n";
    return 2;
  }
  std::ifstream in(argv[1], std::ios::binary);
  int32_t head[3];
  float rad[3];
  in.read(reinterpret_cast<char*>(head), sizeof head);
  in.read(reinterpret_cast<char*>(rad), sizeof rad);
  const int N = head[0], K = head[1], width = head[2];
  const float radius = rad[0], gp3_radius = rad[1], gp3_mu = rad[2];
  std::vector<float> buf(6 * static_cast<size_t>(N));
  in.read(reinterpret_cast<char*>(buf.data()), sizeof(float) * buf.size());
  std::vector<int32_t> kp(K);
  in.read(reinterpret_cast<char*>(kp.data()), sizeof(int32_t) * K);
  int32_t n_local = 0;
  in.read(reinterpret_cast<char*>(&n_local), sizeof n_local);
  std::vector<int32_t> local_off(K + 1);
  std::vector<int32_t> local_tri(3 * static_cast<size_t>(n_local));
  in.read(reinterpret_cast<char*>(local_off.data()), sizeof(int32_t) * local_off.size());
  in.read(reinterpret_cast<char*>(local_tri.data()), sizeof(int32_t) * local_tri.size());
  if (!in || local_off[0] != 0 || local_off[K] != n_local) {
    std::cerr << "short input\n";
    return 1;
  }

  pcl::PointCloud<pcl::PointXYZ>::Ptr xyz(new pcl::PointCloud<pcl::PointXYZ>);
  pcl::PointCloud<pcl::Normal>::Ptr nrm(new pcl::PointCloud<pcl::Normal>);
  pcl::PointCloud<pcl::PointNormal>::Ptr pn(new pcl::PointCloud<pcl::PointNormal>);
  for (int i = 0; i < N; ++i) {
    const float* r = &buf[6 * static_cast<size_t>(i)];
    xyz->push_back(pcl::PointXYZ(r[0], r[1], r[2]));
    pcl::Normal n;
    n.normal_x = r[3];
    n.normal_y = r[4];
    n.normal_z = r[5];
    n.curvature = 0.f;
    nrm->push_back(n);
    pcl::PointNormal q;
    q.x = r[0];
    q.y = r[1];
    q.z = r[2];
    q.normal_x = r[3];
    q.normal_y = r[4];
    q.normal_z = r[5];
    q.curvature = 0.f;
    pn->push_back(q);
  }
  pcl::IndicesPtr idx(new pcl::Indices(kp.begin(), kp.end()));
  pcl::search::KdTree<pcl::PointXYZ>::Ptr tree(new pcl::search::KdTree<pcl::PointXYZ>);
  tree->setInputCloud(xyz);
  std::ofstream out(argv[2], std::ios::binary);

  // --- spin image (PCL defaults: support-angle cos 0 = all points, min neighbours 0)
  {
    using SpinT = pcl::Histogram<153>;
    if (width != 8) {
      std::cerr << "this build writes 153-bin spin images (width 8)\n";
      return 1;
    }
    pcl::SpinImageEstimation<pcl::PointXYZ, pcl::Normal, SpinT> est(width, 0.0, 0);
    est.setInputCloud(xyz);
    est.setInputNormals(nrm);
    est.setIndices(idx);
    est.setSearchMethod(tree);
    est.setRadiusSearch(radius);
    pcl::PointCloud<SpinT> res;
    est.compute(res);
    std::vector<float> v;
    for (const auto& h : res) v.insert(v.end(), h.histogram, h.histogram + 153);
    write_block(out, static_cast<int32_t>(res.size()), 153, v);
  }

  // --- greedy projection triangulation (PCL RoPS tutorial settings) + RoPS
  pcl::PolygonMesh mesh;
  std::vector<pcl::Vertices> triangles;
  {
    pcl::search::KdTree<pcl::PointNormal>::Ptr tree2(new pcl::search::KdTree<pcl::PointNormal>);
    tree2->setInputCloud(pn);
    pcl::GreedyProjectionTriangulation<pcl::PointNormal> gp3;
    gp3.setSearchRadius(gp3_radius);
    gp3.setMu(gp3_mu);
    gp3.setMaximumNearestNeighbors(100);
    gp3.setMaximumSurfaceAngle(M_PI / 4);
    gp3.setMinimumAngle(M_PI / 18);
    gp3.setMaximumAngle(2 * M_PI / 3);
    gp3.setNormalConsistency(false);
    gp3.setInputCloud(pn);
    gp3.setSearchMethod(tree2);
    gp3.reconstruct(triangles);

    pcl::ROPSEstimation<pcl::PointXYZ, pcl::Histogram<135>> rops;
    rops.setInputCloud(xyz);
    rops.setIndices(idx);
    rops.setSearchMethod(tree);
    rops.setRadiusSearch(radius);
    rops.setTriangles(triangles);
    rops.setNumberOfPartitionBins(5);
    rops.setNumberOfRotations(3);
    rops.setSupportRadius(radius);
    pcl::PointCloud<pcl::Histogram<135>> res;
    rops.compute(res);
    std::vector<float> v;
    for (const auto& h : res) v.insert(v.end(), h.histogram, h.histogram + 135);
    write_block(out, static_cast<int32_t>(res.size()), 135, v);
  }

  // --- FPFH
  {
    pcl::FPFHEstimation<pcl::PointXYZ, pcl::Normal, pcl::FPFHSignature33> est;
    est.setInputCloud(xyz);
    est.setInputNormals(nrm);
    est.setIndices(idx);
    est.setSearchMethod(tree);
    est.setRadiusSearch(radius);
    pcl::PointCloud<pcl::FPFHSignature33> res;
    est.compute(res);
    std::vector<float> v;
    for (const auto& h : res) v.insert(v.end(), h.histogram, h.histogram + 33);
    write_block(out, static_cast<int32_t>(res.size()), 33, v);
  }

  // --- SHOT
  {
    pcl::SHOTEstimation<pcl::PointXYZ, pcl::Normal, pcl::SHOT352> est;
    est.setInputCloud(xyz);
    est.setInputNormals(nrm);
    est.setIndices(idx);
    est.setSearchMethod(tree);
    est.setRadiusSearch(radius);
    pcl::PointCloud<pcl::SHOT352> res;
    est.compute(res);
    std::vector<float> v;
    for (const auto& h : res) v.insert(v.end(), h.descriptor, h.descriptor + 352);
    write_block(out, static_cast<int32_t>(res.size()), 352, v);
  }

  {
    std::vector<int32_t> t;
    for (const auto& tri : triangles)
      for (int a = 0; a < 3; ++a) t.push_back(static_cast<int32_t>(tri.vertices[a]));
    write_block(out, static_cast<int32_t>(triangles.size()), 3, t);
  }

  // --- RoPS at each keypoint alone on its own local triangles (relnav's default local mesh);
  // the search surface (support points) stays the whole cloud
  {
    std::vector<float> v;
    v.reserve(static_cast<size_t>(K) * 135);
    int n_nan = 0;
    for (int k = 0; k < K; ++k) {
      std::vector<pcl::Vertices> local;
      for (int32_t t = local_off[k]; t < local_off[k + 1]; ++t) {
        pcl::Vertices tri;
        for (int a = 0; a < 3; ++a)
          tri.vertices.push_back(static_cast<pcl::index_t>(local_tri[3 * static_cast<size_t>(t) + a]));
        local.push_back(tri);
      }
      pcl::PointCloud<pcl::Histogram<135>> res;
      if (!local.empty()) {
        pcl::IndicesPtr one(new pcl::Indices(1, kp[k]));
        pcl::ROPSEstimation<pcl::PointXYZ, pcl::Histogram<135>> rops;
        rops.setInputCloud(xyz);
        rops.setIndices(one);
        rops.setSearchMethod(tree);
        rops.setRadiusSearch(radius);
        rops.setTriangles(local);
        rops.setNumberOfPartitionBins(5);
        rops.setNumberOfRotations(3);
        rops.setSupportRadius(radius);
        rops.compute(res);
      }
      if (res.size() == 1) {
        v.insert(v.end(), res[0].histogram, res[0].histogram + 135);
      } else {
        v.insert(v.end(), 135, std::numeric_limits<float>::quiet_NaN());
        ++n_nan;
      }
    }
    write_block(out, K, 135, v);
    std::cerr << "pcl_reference: RoPS on " << n_local << " local triangles, " << n_nan
              << " keypoints without\n";
  }
  std::cerr << "pcl_reference: " << K << " keypoints, " << triangles.size() << " triangles\n";
  return 0;
}
