#!/usr/bin/env python3
"""Offline checks of Glint's Kubernetes manifests, beside the schema validation of
kubernetes-validate (deploy/k8s/validate.sh runs both).

  validate.py render DIR            the kustomization in DIR rendered without kustomize (the
                                    subset it uses: resources files, namespace, images), on stdout
  validate.py compare A.yaml B.yaml the same objects in both (kustomize's rendering vs render's)
  validate.py check RENDERED.yaml PROTO_DIR
                                    what a schema cannot see: selectors match pods, Services
                                    point at ports that exist, probes at the container's port and
                                    at services the proto declares, the HPA at a Deployment, the
                                    orchestrator's addresses at Services (the workers' at the
                                    headless one), resources, non-root, imagePullPolicy Never

Exits 1 on the first failing command with every problem printed.
"""

import pathlib
import re
import sys

import yaml

CLUSTER_SCOPED = {
    "Namespace", "ClusterRole", "ClusterRoleBinding", "CustomResourceDefinition",
    "PersistentVolume", "StorageClass", "PriorityClass", "IngressClass",
}
SUPPORTED_KEYS = {"apiVersion", "kind", "namespace", "resources", "images"}


def load_all(path):
    with open(path) as f:
        return [d for d in yaml.safe_load_all(f) if d]


def render(directory):
    directory = pathlib.Path(directory)
    k = yaml.safe_load((directory / "kustomization.yaml").read_text())
    unsupported = set(k) - SUPPORTED_KEYS
    if unsupported:
        sys.exit(f"render: kustomization keys this renderer does not implement: {sorted(unsupported)}")
    objects = []
    for resource in k.get("resources", []):
        path = directory / resource
        if not path.is_file():
            sys.exit(f"render: resource {resource} is not a file (directories/remote bases are not implemented)")
        objects.extend(load_all(path))
    namespace = k.get("namespace")
    for o in objects:
        if namespace and o["kind"] not in CLUSTER_SCOPED:
            o["metadata"]["namespace"] = namespace
    for image in k.get("images", []):
        for o in objects:
            for c in pod_containers(o):
                name, tag = split_image(c["image"])
                if name == image["name"]:
                    name = image.get("newName", name)
                    tag = ("@" + image["digest"]) if "digest" in image else (":" + image["newTag"]) if "newTag" in image else tag
                    c["image"] = name + tag
    return objects


def split_image(image):
    if "@" in image:
        name, digest = image.split("@", 1)
        return name, "@" + digest
    name, _, tag = image.rpartition(":")
    if not name or "/" in tag:
        return image, ""
    return name, ":" + tag


def pod_containers(o):
    spec = o.get("spec", {}).get("template", {}).get("spec", {})
    return spec.get("containers", []) + spec.get("initContainers", [])


def key(o):
    return (o["kind"], o["metadata"].get("namespace", ""), o["metadata"]["name"])


def compare(a_path, b_path):
    a = {key(o): o for o in load_all(a_path)}
    b = {key(o): o for o in load_all(b_path)}
    problems = [f"only in {a_path}: {k}" for k in sorted(set(a) - set(b))]
    problems += [f"only in {b_path}: {k}" for k in sorted(set(b) - set(a))]
    problems += [f"differs: {k}" for k in sorted(set(a) & set(b)) if a[k] != b[k]]
    return problems


def proto_services(proto_dir):
    names = set()
    for path in pathlib.Path(proto_dir).rglob("*.proto"):
        text = path.read_text()
        package = re.search(r"^package\s+([\w.]+);", text, re.M)
        for service in re.findall(r"^service\s+(\w+)", text, re.M):
            names.add(f"{package.group(1)}.{service}" if package else service)
    return names


def check(rendered, proto_dir):
    objects = load_all(rendered)
    services_declared = proto_services(proto_dir)
    problems = []
    by_kind = {}
    for o in objects:
        by_kind.setdefault(o["kind"], []).append(o)
    seen = set()
    for o in objects:
        k = key(o)
        if k in seen:
            problems.append(f"{k}: defined twice")
        seen.add(k)
        if o["kind"] not in CLUSTER_SCOPED and not o["metadata"].get("namespace"):
            problems.append(f"{k}: no namespace")

    deployments = {d["metadata"]["name"]: d for d in by_kind.get("Deployment", [])}
    configmaps = {c["metadata"]["name"]: c for c in by_kind.get("ConfigMap", [])}
    services = {s["metadata"]["name"]: s for s in by_kind.get("Service", [])}

    def container_ports(d):
        return {p.get("name"): p["containerPort"] for c in pod_containers(d) for p in c.get("ports", [])}

    for name, d in deployments.items():
        where = f"Deployment {name}"
        template = d["spec"]["template"]
        labels = template["metadata"].get("labels", {})
        selector = d["spec"]["selector"].get("matchLabels", {})
        if not selector or any(labels.get(k) != v for k, v in selector.items()):
            problems.append(f"{where}: selector {selector} does not select its pods {labels}")
        pod = template["spec"]
        psc = pod.get("securityContext", {})
        if psc.get("runAsNonRoot") is not True or psc.get("runAsUser", 0) == 0:
            problems.append(f"{where}: pod securityContext must say runAsNonRoot: true and a non-zero runAsUser")
        ports = set(container_ports(d).values())
        for c in pod_containers(d):
            cw = f"{where} container {c['name']}"
            if not c["image"].startswith("glint:"):
                problems.append(f"{cw}: image {c['image']} is not glint:*")
            if c.get("imagePullPolicy") != "Never":
                problems.append(f"{cw}: imagePullPolicy must be Never (air-gapped)")
            resources = c.get("resources", {})
            for kind in ("requests", "limits"):
                for r in ("cpu", "memory"):
                    if r not in resources.get(kind, {}):
                        problems.append(f"{cw}: no {kind}.{r}")
            csc = c.get("securityContext", {})
            if csc.get("allowPrivilegeEscalation") is not False:
                problems.append(f"{cw}: allowPrivilegeEscalation must be false")
            if "ALL" not in csc.get("capabilities", {}).get("drop", []):
                problems.append(f"{cw}: capabilities must drop ALL")
            for probe in ("livenessProbe", "readinessProbe"):
                p = c.get(probe)
                if not p or "grpc" not in p:
                    problems.append(f"{cw}: no native gRPC {probe}")
                    continue
                if p["grpc"]["port"] not in ports:
                    problems.append(f"{cw}: {probe} port {p['grpc']['port']} is not a containerPort {sorted(ports)}")
                service = p["grpc"].get("service", "")
                if service and service not in services_declared:
                    problems.append(f"{cw}: {probe} asks about {service}, which no .proto declares")
            for source in c.get("envFrom", []):
                ref = source.get("configMapRef", {}).get("name")
                if ref and ref not in configmaps:
                    problems.append(f"{cw}: envFrom ConfigMap {ref} does not exist")

    for name, s in services.items():
        where = f"Service {name}"
        selector = s["spec"].get("selector", {})
        matched = [d for d in deployments.values()
                   if selector and all(d["spec"]["template"]["metadata"].get("labels", {}).get(k) == v for k, v in selector.items())]
        if len(matched) != 1:
            problems.append(f"{where}: selector {selector} matches {len(matched)} Deployments, not 1")
            continue
        ports = container_ports(matched[0])
        for p in s["spec"]["ports"]:
            target = p.get("targetPort", p["port"])
            if (target not in ports) if isinstance(target, str) else (target not in ports.values()):
                problems.append(f"{where}: targetPort {target} is not a port of {matched[0]['metadata']['name']}")

    for h in by_kind.get("HorizontalPodAutoscaler", []):
        where = f"HorizontalPodAutoscaler {h['metadata']['name']}"
        if h["apiVersion"] != "autoscaling/v2":
            problems.append(f"{where}: apiVersion {h['apiVersion']}, want autoscaling/v2")
        ref = h["spec"]["scaleTargetRef"]
        if ref["kind"] != "Deployment" or ref["name"] not in deployments:
            problems.append(f"{where}: scales {ref['kind']} {ref['name']}, which does not exist")
        elif "replicas" in deployments[ref["name"]]["spec"]:
            problems.append(f"{where}: Deployment {ref['name']} sets replicas, which the HPA owns")

    # The orchestrator's addresses: Services of this namespace, the workers' a headless one.
    for cm in configmaps.values():
        data = cm.get("data", {})
        for var in ("GLINT_CAMERA_ADDR", "GLINT_ESTIMATION_ADDR", "GLINT_WORKERS"):
            if var not in data:
                continue
            value = data[var]
            headless = value.startswith("dns:")
            host, _, port = value.removeprefix("dns:").rpartition(":")
            where = f"ConfigMap {cm['metadata']['name']} {var}={value}"
            s = services.get(host)
            if s is None:
                problems.append(f"{where}: no Service {host}")
                continue
            if port.isdigit() and int(port) not in [p["port"] for p in s["spec"]["ports"]]:
                problems.append(f"{where}: Service {host} has no port {port}")
            if headless and s["spec"].get("clusterIP") != "None":
                problems.append(f"{where}: dns: re-resolves to every worker only through a headless Service (clusterIP: None)")
    if not any(cm.get("data", {}).get("GLINT_WORKERS") for cm in configmaps.values()):
        problems.append("no ConfigMap gives the orchestrator GLINT_WORKERS")

    for o in objects:
        print(f"  checked {o['kind']}/{o['metadata']['name']}")
    return problems


def main(argv):
    if len(argv) >= 2 and argv[1] == "render" and len(argv) == 3:
        yaml.safe_dump_all(render(argv[2]), sys.stdout, sort_keys=False)
        return 0
    if len(argv) == 4 and argv[1] == "compare":
        problems = compare(argv[2], argv[3])
    elif len(argv) == 4 and argv[1] == "check":
        problems = check(argv[2], argv[3])
    else:
        print(__doc__, file=sys.stderr)
        return 2
    for p in problems:
        print(f"INVALID: {p}")
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
